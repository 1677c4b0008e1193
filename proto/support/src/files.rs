//! Files in and out, the one way every part does it: [`read_capped`] (how every untrusted file is
//! read whole: maps, routes, rigs, configs, datasets, results to resume; step logs are read
//! record by record, each capped), [`write_atomic`] (how every result
//! file is written), and [`FileError`], a file that cannot be read or written, naming the path
//! and the problem (the dataset and step-log readers return it as `DatasetError` and `LogError`).

use std::io::Read;
use std::path::{Path, PathBuf};

/// A file that cannot be read or written, with its path and the problem.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The operating system refused a read or write.
    #[error("{path}: {source}")]
    Io {
        /// The file (or folder) at fault.
        path: PathBuf,
        /// The error the operating system gave.
        source: std::io::Error,
    },
    /// The file is unusable for a reason other than I/O: too large, malformed, inconsistent.
    #[error("{path}: {problem}")]
    Invalid {
        /// The file (or folder) at fault.
        path: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
}

impl FileError {
    /// An I/O failure on `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A non-I/O problem with `path`, described by `problem`.
    pub fn invalid(path: &Path, problem: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.to_path_buf(),
            problem: problem.into(),
        }
    }

    /// A failed [`read_capped`] of `path`.
    pub fn read(path: &Path, error: CappedReadError) -> Self {
        match error {
            CappedReadError::Io(source) => Self::io(path, source),
            other => Self::invalid(path, other.to_string()),
        }
    }
}

/// Why [`read_capped`] failed.
#[derive(Debug, thiserror::Error)]
pub enum CappedReadError {
    /// The file could not be opened or read.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The file holds more than `limit` bytes.
    #[error("over the {limit}-byte limit")]
    TooLarge {
        /// The cap, bytes.
        limit: u64,
    },
    /// A text file that is not valid UTF-8.
    #[error("not UTF-8 text")]
    NotUtf8,
}

/// The whole file at `path`, refusing one over `limit` bytes. It reads through
/// `File::take(limit + 1)`, so a file that grows while it is read, or a device that never ends,
/// costs at most `limit + 1` bytes of memory.
pub fn read_capped(path: &Path, limit: u64) -> Result<Vec<u8>, CappedReadError> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)?
        .take(limit.saturating_add(1))
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(CappedReadError::TooLarge { limit });
    }
    Ok(bytes)
}

/// [`read_capped`] for a text file.
pub fn read_capped_text(path: &Path, limit: u64) -> Result<String, CappedReadError> {
    String::from_utf8(read_capped(path, limit)?).map_err(|_| CappedReadError::NotUtf8)
}

/// Write `bytes` to `path` through a temporary file beside it and a rename, so a reader (or a
/// resume) never sees half a file: a full disk or a file-size limit leaves the previous
/// version whole, and the temporary file is removed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    if let Err(error) = std::fs::write(&tmp, bytes) {
        let _ = std::fs::remove_file(&tmp);
        return Err(error);
    }
    std::fs::rename(&tmp, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capped_reads_refuse_files_over_the_limit() {
        let dir = std::env::temp_dir().join(format!("ssrdrive-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ten.txt");
        std::fs::write(&path, "0123456789").unwrap();
        assert_eq!(read_capped_text(&path, 10).unwrap(), "0123456789");
        let refused = read_capped(&path, 9).unwrap_err();
        assert_eq!(refused.to_string(), "over the 9-byte limit");
        std::fs::write(&path, [0xff, 0xfe]).unwrap();
        assert!(matches!(
            read_capped_text(&path, 10),
            Err(CappedReadError::NotUtf8)
        ));
        let missing = read_capped(&dir.join("missing"), 10).unwrap_err();
        assert!(matches!(missing, CappedReadError::Io(_)), "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
