//! Compiles `landing/v1/*.proto` with protox (pure Rust, no system `protoc`) and writes the encoded
//! descriptor set next to the generated code for server reflection and MCAP schemas.

use std::path::PathBuf;

use prost::Message;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?);
    let mut files = Vec::new();
    for dir in ["landing/v1", "google/rpc"] {
        let dir = root.join(dir);
        println!("cargo:rerun-if-changed={}", dir.display());
        for entry in std::fs::read_dir(&dir)? {
            let path = entry?.path();
            if path.extension().is_some_and(|e| e == "proto") {
                println!("cargo:rerun-if-changed={}", path.display());
                files.push(path);
            }
        }
    }
    files.sort();

    let fds = protox::compile(&files, [&root])?;
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(out_dir.join("landing_descriptor.bin"), fds.encode_to_vec())?;

    tonic_prost_build::configure()
        // Scans and images as `bytes::Bytes`: a retried or re-sent frame clones a reference
        // count, not the buffer.
        .bytes(".landing.v1")
        .build_server(true)
        .build_client(true)
        .compile_fds(fds)?;
    Ok(())
}
