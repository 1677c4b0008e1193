//! How the command lines (`sim-bridge`, `ssr-agent`) print an error: the message and each cause
//! after it, leaving out a cause whose text the message already holds (many errors name their
//! I/O cause in their own message, and printing it twice only adds noise).

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
