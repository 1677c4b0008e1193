//! Training: expert datasets to SSR samples ([`data`], [`augment`], [`loader`]), TCP's
//! imitation losses plus SSR's future-BEV loss, the hazard head's and the occupancy head's
//! ([`loss`], [`auxiliary`]: [`hazard`], [`occupancy`]), the loop with AdamW, schedule,
//! checkpoints ([`run`]) and resume state ([`resume`]), configured by [`config`],
//! and its open-loop validation metrics ([`validation`]).

pub mod augment;
pub mod auxiliary;
pub mod config;
pub mod data;
pub mod error;
pub mod gamma;
pub mod hazard;
pub mod light;
pub mod loader;
pub mod loss;
pub mod occupancy;
pub mod resume;
pub mod run;
pub mod validation;
