//! sim-bridge: a kinematic driving simulator on OpenDRIVE maps that scores routes the way the
//! CARLA leaderboard 1.0 does.
//!
//! Parts, one module each: [`camera`] (rigs in CARLA's sensor description), [`map`] (OpenDRIVE through the `xodr` crate, lane graph, traffic
//! lights and stop signs), [`towngen`] (the deterministic generator of the bundled towns),
//! [`route`] (route files, dense routes, global plan, route follower), [`world`] (the 20 Hz
//! lockstep world), [`scoring`] (the leaderboard criteria and results).

pub mod agent;
pub mod camera;
pub mod client;
pub mod dataset;
pub mod error_text;
pub mod eval;
pub mod expert;
pub mod files;
pub mod image;
pub mod map;
pub mod render;
pub mod replay;
pub mod route;
pub mod scoring;
pub mod towngen;
pub mod world;
