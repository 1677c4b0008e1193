//! Compiles `ssrdrive/v1/agent.proto` with protox (a protobuf compiler in pure Rust, so no
//! `protoc` is needed), generates the prost messages and tonic client/server from the result, and
//! writes the encoded file descriptor set that server reflection serves.

use std::path::PathBuf;

use prost::Message as _;

const PROTO: &str = "ssrdrive/v1/agent.proto";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed={PROTO}");
    let descriptors = protox::compile([PROTO], ["."])?;
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(
        out_dir.join("ssrdrive_descriptor.bin"),
        descriptors.encode_to_vec(),
    )?;
    tonic_prost_build::configure()
        .build_client(true)
        .build_server(true)
        .compile_fds(descriptors)?;
    Ok(())
}
