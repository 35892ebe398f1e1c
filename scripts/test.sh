#!/usr/bin/env bash
# The whole test suite: format, lints, the Rust tests (unit, property, doc, end-to-end over loopback
# gRPC with the real model and real recordings), then the cross-language and deployment checks:
# the Python MCAP reader, the segmentation smoke train + ONNX parity check, a Python grpcio client,
# the evaluation slice (fails on any unsafe site), and the deploy manifests/config/serve check.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

bash scripts/setup.sh
export ORT_DYLIB_PATH="$root/.ort/libonnxruntime.so"
py="$root/.venv/bin/python"

step() { printf '\n=== %s\n' "$*"; }

step "format and lints"
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --locked -- -D warnings

step "Rust tests (unit, property, doc, end-to-end)"
cargo test --workspace --locked

step "release binaries"
cargo build --release --locked -p landing-server -p landing-client -p landing-sim --bins

step "independent MCAP reader (Python mcap + protobuf decoder)"
tmp=$(mktemp -d)
server_pid=""
cleanup() {
  [ -n "$server_pid" ] && kill -TERM "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
target/release/landing-sim record --seed 7 --frames 12 --out "$tmp/check.mcap"
"$py" sim/tests/python/check_mcap.py "$tmp/check.mcap"
"$py" sim/tests/python/check_mcap.py samples/rooftops.mcap

step "segmentation: smoke train, export, parity with PyTorch, shipped model signature"
bash models/training/smoke.sh

step "a client that is not ours (Python grpcio) and the evaluation slice, against a real server"
target/release/landing-server serve --listen 127.0.0.1:50051 --metrics-listen "" &
server_pid=$!
for _ in $(seq 1 150); do target/release/landing info >/dev/null 2>&1 && break; sleep 0.2; done
"$py" client/examples/python/detect_one_frame.py --server 127.0.0.1:50051 --recording samples/rooftops.mcap
target/release/landing eval --scenarios small --out "$tmp/eval-small" --gate model
kill -TERM "$server_pid"; wait "$server_pid"; server_pid=""

step "deployment: manifests, container recipes, shipped config, serving the sample with it"
LANDING_BIN_DIR="$root/target/release" bash deploy/check.sh

printf '\nall checks passed\n'
