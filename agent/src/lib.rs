//! ssr-agent: the SSR end-to-end driving network in Burn, the controllers that turn its outputs
//! into vehicle control, and the per-episode inference API the gRPC server uses.
//!
//! - [`pose`]: ego poses and the ego motion between ticks.
//! - [`model`]: the network (backbone, BEV encoder, Scenes TokenLearner, TCP head, FFP).
//! - [`control`]: pure pursuit, speed PID, Beta rules and fusion (crate `ssr-control`).
//! - [`history`]: how the network gets its history BEV (a setting training and serving share).
//! - [`policy`]: per-episode state and the step / batched-step API.
//! - [`checkpoint`]: weights with their config in one safetensors file.
//! - [`train`]: losses (imitation + future-BEV) used by training.
//! - [`serve`]: the gRPC agent server (sessions, batching, health, metrics).
//! - [`device`]: backend selection (CPU by default, wgpu behind the `wgpu` feature).
//!
//! Conventions: world frame = OpenDRIVE map frame (x east, y north, z up, m); ego frame = x
//! forward, y left, z up, origin at the centre of the vehicle box on the ground; control in
//! CARLA's convention (steer +1 = full right). What the agent shares with the simulator (camera
//! rigs, controls, commands, the dataset format, wire conversions) is the contract crate
//! `ssrdrive_proto`; this crate does not depend on the simulator.

pub mod checkpoint;
pub use ssr_control as control;
pub mod device;
pub mod history;
pub mod model;
pub mod policy;
pub mod pose;
pub mod serve;
pub mod train;
