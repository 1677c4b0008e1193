//! [`FileError`]: a file that cannot be read or written, naming the path and the problem. The
//! dataset and step-log readers share it (as `DatasetError` and `LogError`). And
//! [`write_atomic`], how every result file is written.

use std::path::{Path, PathBuf};

/// A file that cannot be read or written, with its path and the problem.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
}

impl FileError {
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub fn invalid(path: &Path, problem: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.to_path_buf(),
            problem: problem.into(),
        }
    }
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
