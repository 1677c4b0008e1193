//! sim-bridge: a kinematic driving simulator on OpenDRIVE maps that scores routes the way the
//! CARLA leaderboard 1.0 does.
//!
//! Parts, one module each: [`map`] (OpenDRIVE through the `xodr` crate, lane graph, traffic
//! lights and stop signs), [`towngen`] (the deterministic generator of the bundled towns).

pub mod map;
pub mod towngen;
