#!/usr/bin/env bash
# The Foxglove live view's cost to the service (BENCHMARKS.md, "Live view"): the same load test
# against a server without the live view, with it and no viewer, with a viewer that reads every
# channel, and with a viewer that has stalled; ROUNDS rounds in that order (default 2).
# Needs the release binaries and `bash scripts/python-env.sh bench server/benches/requirements.txt`.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
bin=target/release
py=.venvs/bench/bin/python
export ORT_DYLIB_PATH="$root/.ort/libonnxruntime.so"
load=(loadtest samples/rooftops.mcap --streams 4 --rate 10 --duration 20)

serve() {
  "$bin/landing-server" serve --listen 127.0.0.1:50061 --metrics-listen 127.0.0.1:9471 "$@" \
    >/dev/null 2>&1 &
  server=$!
  for _ in $(seq 1 100); do "$bin/landing" --server http://127.0.0.1:50061 info >/dev/null 2>&1 && return; sleep 0.2; done
  echo "server did not start"; exit 1
}
stop() { kill -TERM "$server"; wait "$server" || true; }
live() { curl -s 127.0.0.1:9471/metrics | grep -E '^landing_live_view_(frames|dropped)_total ' | tr '\n' ' '; }
measure() {
  echo "--- $1"
  "$bin/landing" --server http://127.0.0.1:50061 "${load[@]}" | grep -E 'throughput|latency'
  echo "    $(live)"
}

for round in $(seq 1 "${ROUNDS:-2}"); do
  echo "=== round $round"
  serve; measure "live view off"; stop
  serve --foxglove-listen 127.0.0.1:8765; measure "live view on, no viewer"; stop
  serve --foxglove-listen 127.0.0.1:8765
  "$py" server/benches/foxglove_viewer.py ws://127.0.0.1:8765 --seconds 22 &
  viewer=$!; sleep 1; measure "one viewer reading every channel"; wait "$viewer"; stop
  serve --foxglove-listen 127.0.0.1:8765
  "$py" server/benches/foxglove_viewer.py ws://127.0.0.1:8765 --seconds 22 --stall &
  viewer=$!; sleep 1; measure "one stalled viewer (subscribed, reads nothing)"; wait "$viewer"; stop
done
