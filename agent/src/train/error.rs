//! Why a training run could not start or go on: one error type for the loop
//! ([`super::run`]) and its resume state ([`super::resume`]).

use std::path::PathBuf;

use ssrdrive_proto::dataset::DatasetError;

use crate::checkpoint::CheckpointError;
use crate::device::BackendUnavailable;

/// Why a training run could not start or go on.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The dataset could not be read or has no usable samples.
    #[error("dataset: {0}")]
    Dataset(#[from] DatasetError),
    /// A checkpoint could not be read or written.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// The backend asked for is not in this build.
    #[error(transparent)]
    Backend(#[from] BackendUnavailable),
    /// The training config is invalid (the message names the field).
    #[error("training config: {0}")]
    Config(String),
    /// A file of the run's folder could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The resume state is missing, incomplete or does not fit the run.
    #[error("cannot resume from {path}: {problem}")]
    Resume {
        /// The run folder or resume state at fault.
        path: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
    /// The loss became NaN or infinite.
    #[error("step {step}: the loss is {value}; lower the learning rate or check the data")]
    Diverged {
        /// The optimiser step whose loss it was, from 1.
        step: u64,
        /// The loss.
        value: f32,
    },
}
