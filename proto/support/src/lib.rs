//! What every ssrdrive crate does alike and is not the simulator-agent contract
//! (`ssrdrive-proto` is): [`files`], capped reads of untrusted files and atomic writes;
//! [`error_text`], how errors are printed and how client-supplied values are clipped in them;
//! [`logging`], how both binaries log; [`ranges`], range checks of settings; [`stats`],
//! percentiles of measured samples.

#![forbid(unsafe_code)]

pub mod error_text;
pub mod files;
pub mod logging;
pub mod ranges;
pub mod stats;
