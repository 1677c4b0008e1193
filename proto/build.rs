//! Compiles `ssrdrive/v1/{agent,log}.proto` with protox (a protobuf compiler in pure Rust, so no
//! `protoc` is needed), generates the prost messages and tonic client/server from the result, and
//! writes the encoded file descriptor set that server reflection serves.

use std::path::PathBuf;

use prost::Message as _;

const PROTOS: [&str; 2] = ["ssrdrive/v1/agent.proto", "ssrdrive/v1/log.proto"];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for proto in PROTOS {
        println!("cargo:rerun-if-changed={proto}");
    }
    let descriptors = protox::compile(PROTOS, ["."])?;
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
