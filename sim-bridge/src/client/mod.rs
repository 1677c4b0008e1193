//! Talking to an agent server over gRPC (`ssrdrive.v1`).
//!
//! - [`grpc`]: [`grpc::GrpcAgent`], an [`crate::driver::Agent`] backed by a remote server.
//! - [`load`]: a fixed-rate load generator (no coordinated omission).
//! - [`local`]: [`local::LocalServer`], an `ssr-agent serve` child process on loopback.

pub mod grpc;
pub mod load;
pub mod local;
