#!/usr/bin/env bash
# The whole test suite: the segmentation smoke train + ONNX parity check (first: see "Disk"), format,
# lints, the Rust tests (unit, property, doc, end-to-end over loopback gRPC with the real model and
# real recordings), then the cross-language and deployment checks: the Python MCAP reader, a Python
# grpcio client and the stock Python reflection client, the evaluation slice, single-frame and fused
# (fails on any unsafe site), the deploy manifests/config/serve check, and a seeded smoke run of
# every cargo-fuzz target (RELIABILITY.md).
# Each Python step uses its own venv under .venvs/ (scripts/python-env.sh): checks here, train in
# models/training/smoke.sh, deploy in deploy/check.sh.
#
# Disk: kept build outputs add up to about 14 GB (PyTorch's venv 5.6 GB, the test build 3.9, the
# release build 1.8, the fuzz targets 2.0). With LANDING_TEST_PRUNE=1 (.ci/run sets it: a clean
# clone that is thrown away) each step's outputs are removed once no later step needs them, so the
# suite needs only its largest step, PyTorch's install (8.5 GB at its peak, its wheels beside what
# they unpack), which therefore runs first; every later step stays under 4.5 GB.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
. scripts/lib.sh

bash scripts/setup.sh
export ORT_DYLIB_PATH="$root/.ort/libonnxruntime.so"

# Each step's header says how much disk is left.
step() { printf '\n=== %s  (%s free)\n' "$*" "$(df -h --output=avail . | tail -1 | tr -d ' ')"; }
prune() {
  if [ "${LANDING_TEST_PRUNE:-0}" = 1 ]; then
    echo "prune: $*"
    "$@"
  fi
}

step "segmentation: smoke train, export, parity with PyTorch, shipped model signature"
bash models/training/smoke.sh
prune rm -rf .venvs/train

step "format and lints"
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --locked -- -D warnings
python3 scripts/check-imports.py
# The SDK stays light: no simulator, image codec or MCAP in its tree; no simulator in the server's.
if cargo tree --locked -p landing-client -e normal --prefix none | grep -E '^(landing-sim|image|mcap) '; then
  echo "landing-client depends on the crates above"; exit 1
fi
if cargo tree --locked -p landing-server -e normal --prefix none | grep -E '^landing-sim '; then
  echo "landing-server depends on landing-sim"; exit 1
fi

step "Rust tests (unit, property, doc, end-to-end)"
bash scripts/setup-postgres.sh  # the catalog's conformance suite starts a PostgreSQL + PostGIS
cargo test --workspace --locked
prune cargo clean --profile dev  # the test build: every later step runs the release binaries

step "release binaries"
cargo build --release --locked -p landing-server -p landing-cli -p landing-sim --bins
bin=$(release_bin_dir)  # target/release unless CARGO_TARGET_DIR or a cargo config says otherwise

step "independent MCAP reader (Python mcap + protobuf decoder + Foxglove's own schema classes)"
py=$(bash scripts/python-env.sh checks sim/tests/python/requirements.txt client/examples/python/requirements.txt)
tmp=$(mktemp -d)
server_pid=""
cleanup() {
  [ -n "$server_pid" ] && kill -TERM "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
"$bin/landing-sim" record --seed 7 --frames 12 --out "$tmp/check.mcap"
"$py" sim/tests/python/check_mcap.py "$tmp/check.mcap"
"$py" sim/tests/python/check_mcap.py samples/rooftops.mcap

step "a client that is not ours (Python grpcio) and the evaluation slice, against a real server"
"$bin/landing-server" serve --listen 127.0.0.1:50051 --metrics-listen "" &
server_pid=$!
for _ in $(seq 1 150); do "$bin/landing" info >/dev/null 2>&1 && break; sleep 0.2; done
"$py" client/examples/python/detect_one_frame.py --server 127.0.0.1:50051 --recording samples/rooftops.mcap
# A replay's output: the inputs and each answer drawn, every channel read with the stock readers.
"$bin/landing" replay samples/rooftops.mcap --out "$tmp/replay.mcap"
"$py" sim/tests/python/check_mcap.py "$tmp/replay.mcap" --replay
# The stock reflection client (grpcio-reflection: v1alpha only) describes and calls the API.
"$py" client/examples/python/reflect.py --server 127.0.0.1:50051
"$bin/landing" eval --scenarios small --out "$tmp/eval-small" --gate model
# The same approaches as fused streams, beside single frames: fails on an unsafe site in either.
"$bin/landing" eval --scenarios small --out "$tmp/eval-small-stream" --stream --gate model
kill -TERM "$server_pid"; wait "$server_pid"; server_pid=""

step "deployment: manifests, container recipes, shipped config, serving the sample with it"
LANDING_BIN_DIR="$bin" bash deploy/check.sh
prune cargo clean --release  # the fuzz targets build in their own directory

step "fuzz smoke: every cargo-fuzz target, 20 000 runs from its seed corpus, seeded (RELIABILITY.md)"
command -v cargo-fuzz >/dev/null || cargo install --locked cargo-fuzz@0.13.2
(
  cd fuzz
  # libFuzzer's coverage instrumentation only (-s none): address sanitizing needs a nightly compiler.
  cargo fuzz build -s none
  for target in $(cargo fuzz list); do
    mkdir -p "$tmp/fuzz/$target"
    log="$tmp/fuzz/$target.log"
    if ! cargo fuzz run -s none "$target" "$tmp/fuzz/$target" "corpus/$target" -- \
      -seed=1 -runs="${FUZZ_RUNS:-20000}" -rss_limit_mb=2048 -timeout=10 >"$log" 2>&1; then
      tail -n 60 "$log"; echo "fuzz target $target failed"; exit 1
    fi
    printf '%s: %s\n' "$target" "$(grep -E '^Done [0-9]+ runs' "$log")"
  done
)

printf '\nall checks passed\n'
