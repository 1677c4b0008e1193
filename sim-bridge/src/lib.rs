//! sim-bridge: a kinematic driving simulator on OpenDRIVE maps that scores routes the way the
//! CARLA leaderboard 1.0 does.
//!
//! Parts, one module each: [`map`] (OpenDRIVE through the `xodr` crate, lane graph, traffic
//! lights and stop signs), [`towngen`] (the deterministic generator of the bundled towns),
//! [`route`] (route files, dense routes, global plan, route follower), [`world`] (the 20 Hz
//! lockstep world), [`render`] (cameras and top-down pictures), [`driver`] (what drives the
//! ego), [`expert`] (the privileged driver), [`scoring`] (the leaderboard criteria and results),
//! [`eval`] (route runs), [`dataset`] (recording), [`replay`] (step logs), [`client`] (agent
//! servers over gRPC). What it shares with the agent (rigs, controls, commands, the dataset
//! format, wire conversions, file reads) is the contract crate `ssrdrive_proto`.

#![forbid(unsafe_code)]

pub mod client;
pub mod dataset;
pub mod driver;
pub mod eval;
pub mod expert;
pub mod map;
pub mod render;
pub mod replay;
pub mod route;
pub mod scoring;
pub mod towngen;
pub mod world;
