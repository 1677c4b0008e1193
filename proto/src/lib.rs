//! Rust bindings of the ssrdrive agent service, generated at build time from
//! `proto/ssrdrive/v1/agent.proto` (the one source of truth; read it for every field's unit and
//! frame). Both the server (`ssr-agent serve`) and the simulator-side client (`sim-bridge`) use
//! these types.

/// Package `ssrdrive.v1`: messages, `agent_service_client` and `agent_service_server`.
pub mod v1 {
    tonic::include_proto!("ssrdrive.v1");

    /// The encoded `FileDescriptorSet` of the package, for gRPC server reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/ssrdrive_descriptor.bin"));
}
