//! How the command lines (`sim-bridge`, `ssr-agent`) print an error: the message and each cause
//! after it, leaving out a cause whose text the message already holds (many errors name their
//! I/O cause in their own message, and printing it twice only adds noise).

/// Longest client-supplied value an error message repeats, characters.
pub const CLIPPED_CHARS: usize = 64;

/// A client-supplied value as error messages repeat it: whole up to [`CLIPPED_CHARS`]
/// characters, else its start and its size, so a 20,000-character id cannot blow up a reply
/// (gRPC clients refuse status headers over 16 KiB).
pub fn clipped(value: &str) -> String {
    match value.char_indices().nth(CLIPPED_CHARS) {
        None => value.to_string(),
        Some((end, _)) => format!("{}... ({} bytes)", &value[..end], value.len()),
    }
}

/// `error` and its causes, joined with ": ", each cause once.
pub fn error_text(error: &anyhow::Error) -> String {
    let mut text = error.to_string();
    for cause in error.chain().skip(1) {
        let cause = cause.to_string();
        if !text.contains(&cause) {
            text.push_str(": ");
            text.push_str(&cause);
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("reading {path}: {source}")]
    struct Read {
        path: String,
        source: std::io::Error,
    }

    #[test]
    fn long_values_are_clipped() {
        assert_eq!(clipped("rgb_front"), "rgb_front");
        let long = "é".repeat(20_000);
        let shown = clipped(&long);
        assert!(shown.starts_with(&"é".repeat(CLIPPED_CHARS)), "{shown}");
        assert!(shown.ends_with("... (40000 bytes)"), "{shown}");
    }

    #[test]
    fn causes_are_printed_once() {
        let missing = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let error = anyhow::Error::new(Read {
            path: "a.json".into(),
            source: missing,
        })
        .context("loading the config");
        assert_eq!(
            error_text(&error),
            "loading the config: reading a.json: no such file"
        );
    }
}
