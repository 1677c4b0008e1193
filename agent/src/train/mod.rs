//! Training: expert datasets to SSR samples ([`data`], [`augment`], [`loader`]), TCP's
//! imitation losses plus SSR's future-BEV loss, the training-only hazard probe's and the
//! occupancy head's ([`loss`], [`probes`]: [`hazard`], [`occupancy`]),
//! the loop with AdamW, schedule, checkpoints and resume ([`run`]), configured by [`config`],
//! and its open-loop validation metrics ([`validation`]).

pub mod augment;
pub mod config;
pub mod data;
pub mod hazard;
pub mod loader;
pub mod loss;
pub mod occupancy;
pub mod probes;
pub mod run;
pub mod special;
pub mod validation;
