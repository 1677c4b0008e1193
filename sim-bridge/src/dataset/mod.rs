//! Recording expert driving datasets (the format and the reader are the contract crate's
//! `ssrdrive_proto::dataset`): the [`recorder`] that writes one episode while the expert drives,
//! and the [`collect`] loop over many routes (parallel, resumable).
//!
//! Guarantees: an episode folder exists only once its episode is complete (it is written as
//! `episodes/.<name>.partial` and renamed at the end), so an interrupted collection loses at
//! most the episodes in flight, which a resumed collection redoes from scratch, and never
//! holds a frame twice. The manifest is rewritten (atomically) after every episode.

pub mod collect;
pub mod recorder;
