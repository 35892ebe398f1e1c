#!/usr/bin/env bash
# The main job on the embedded default: set up, build, start the service with the shipped model,
# replay the sample recording through it as a fused stream placed in midtown Manhattan (ranked sites
# per frame; the stream feeds the fleet's catalog), print the landing sites the catalog now knows
# near its roofs, write overlay PNGs of a few frames to out/ (camera view + top-down, like the
# paper's Fig. 4), then stop the server.
# Installs only what that needs: the ONNX Runtime library (scripts/setup.sh); no Python.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
. scripts/lib.sh

bash scripts/setup.sh
export ORT_DYLIB_PATH="$root/.ort/libonnxruntime.so"
cargo build --release --locked -p landing-server -p landing-cli --bins
bin=$(release_bin_dir)  # target/release unless CARGO_TARGET_DIR or a cargo config says otherwise

addr=127.0.0.1:50051
server_pid=""
trap '[ -n "$server_pid" ] && kill -TERM "$server_pid" 2>/dev/null; wait 2>/dev/null' EXIT
"$bin/landing-server" serve --listen "$addr" --metrics-listen "" &
server_pid=$!
for _ in $(seq 1 150); do "$bin/landing" info --server "http://$addr" >/dev/null 2>&1 && break; sleep 0.2; done

"$bin/landing" info --server "http://$addr"
# Streams fuse by default; a WGS-84 origin gives the sites latitude and longitude and lets the
# stream feed the fleet's catalog (the server's default: SQLite in data/catalog.sqlite).
origin=40.7536,-73.9832
"$bin/landing" replay samples/rooftops.mcap --origin "$origin" --server "http://$addr"

# Ask the catalog what it knows near the sample's roofs.
# The catalog's writer gathers a batch for up to catalog.flush_interval_s (1 s): ask until it
# answers with a site this replay confirmed (an earlier run's are older), for at most 10 s, then
# show everything it knows there.
for _ in $(seq 1 50); do
  "$bin/landing" sites --near "$origin" --radius 1000 --max-age-s 30 --json --server "http://$addr" 2>/dev/null |
    grep -q '"distance_m"' && break
  sleep 0.2
done
"$bin/landing" sites --near "$origin" --radius 1000 --server "http://$addr"
mkdir -p out
for frame in 0 7 14; do
  "$bin/landing" render samples/rooftops.mcap --frame "$frame" --server "http://$addr" --out "out/frame-$frame.png"
done
echo "overlays: out/frame-0.png out/frame-7.png out/frame-14.png"

kill -TERM "$server_pid"; wait "$server_pid"; server_pid=""
