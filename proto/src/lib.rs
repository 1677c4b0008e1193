//! The contract between the simulator and the agent, and nothing else: both `sim-bridge` and
//! `ssr-agent` depend on this crate and never on each other.
//!
//! - [`v1`]: Rust bindings of the `ssrdrive.v1` service, generated at build time from
//!   `proto/ssrdrive/v1/*.proto` (the one source of truth; read it for every field's unit and
//!   frame), and [`wire`], the conversions between the types below and those messages.
//! - [`camera`]: camera rigs in CARLA's sensor description and their projection.
//! - [`control`]: the vehicle [`control::Control`]; [`command`]: CARLA's RoadOption and its
//!   one-hot encoding.
//! - [`dataset`]: the on-disk format of driving datasets and its reader; [`image`]: RGB8
//!   images in and out of PNG.
//! - [`vehicle`]: the sedan the simulator drives and the controller is set up for.
//! - [`frames`]: the world and ego frames, angle wrapping and world-to-ego.
//! - [`TICK_HZ`], [`TICK_S`]: the tick both sides step at; [`EPISODE_KEY_HEADER`],
//!   [`REPLICA_HEADER`]: the metadata that keeps an episode on one replica behind a balancer.

#![forbid(unsafe_code)]

/// Simulation and control ticks per second: the CARLA leaderboard's 20 Hz, at which the
/// simulator steps, the agent is asked for a control, and every count of ticks is kept.
pub const TICK_HZ: u32 = 20;
/// One tick, seconds (exactly the nearest double to 0.05).
pub const TICK_S: f64 = 1.0 / TICK_HZ as f64;

/// gRPC metadata a client sends with `StartEpisode`, every `Step` and `EndEpisode` of an
/// episode: a key of its choosing, the same for the whole episode, that a load balancer in front
/// of several servers hashes so that every call of the episode reaches the replica holding its
/// temporal state (`docker/envoy/`). A `Drive` stream stays on one replica by itself.
pub const EPISODE_KEY_HEADER: &str = "x-ssrdrive-episode-key";
/// gRPC metadata a server sends with every answer and error: its replica id
/// (`ssr-agent serve --replica-id`).
pub const REPLICA_HEADER: &str = "x-ssrdrive-replica";

pub mod camera;
pub mod command;
pub mod control;
pub mod dataset;
pub mod frames;
pub mod image;
pub mod vehicle;
pub mod wire;

/// Package `ssrdrive.v1`: messages, `agent_service_client` and `agent_service_server`.
// Generated code: the .proto comments are its docs.
#[allow(missing_docs)]
pub mod v1 {
    tonic::include_proto!("ssrdrive.v1");

    /// The encoded `FileDescriptorSet` of the package, for gRPC server reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/ssrdrive_descriptor.bin"));
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_tick_is_the_leaderboards() {
        assert_eq!(
            super::TICK_S,
            0.05,
            "bit for bit, as the constant it replaces"
        );
        assert_eq!(super::TICK_S * super::TICK_HZ as f64, 1.0);
    }
}
