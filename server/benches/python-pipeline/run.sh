#!/usr/bin/env bash
# The unary model-mode frame side by side with the plain Python pipeline (pipeline.py) on the same
# recordings and machine (issue 42). Each round starts a server, times every frame of SET with
# `landing eval --modes model --window 1` (one unary call at a time, as a client sees it, and the
# server's own decode-to-polylabel time), stops it, and then times pipeline.py on the same frames.
# Prints each round's p50s and writes everything under OUT.
#
# Usage: run.sh SET [ROUNDS (3)] [OUT (target/python-pipeline)]
#   SET: a directory of recordings, e.g. `landing-sim scenarios --seed 5807 --worlds 6
#   --buildings 6 --frames 4 --out SET`. Needs the release binaries and ONNX Runtime
#   (scripts/setup.sh); LANDING__* settings in the environment apply to the server.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../../.." && pwd)
set_dir=$(cd "$1" && pwd)
rounds=${2:-3}
out=${3:-$root/target/python-pipeline}
. "$root/scripts/lib.sh"
bin=$(cd "$root" && release_bin_dir)  # honours CARGO_TARGET_DIR
export ORT_DYLIB_PATH=${ORT_DYLIB_PATH:-$root/.ort/libonnxruntime.so}
py=$(bash "$here/setup.sh")
mkdir -p "$out"
port=50151
url="http://127.0.0.1:$port"

p50() { # results.json → "round trip p50, server p50" in ms
  "$py" - "$1" << 'PY'
import json, statistics, sys
records = json.load(open(sys.argv[1]))["records"]
print(f"{statistics.median(r['round_trip_ms'] for r in records):.2f} "
      f"{statistics.median(r['step_ms'][-1] for r in records):.2f}")
PY
}

echo "round  service round trip p50  service server p50  python p50 (ms)"
for round in $(seq "$rounds"); do
  LANDING__CATALOG__ENABLED=false "$bin/landing-server" serve --listen "127.0.0.1:$port" \
    --metrics-listen "" > "$out/server-$round.log" 2>&1 &
  server=$!
  for _ in $(seq 100); do "$bin/landing" --server "$url" info > /dev/null 2>&1 && break; sleep 0.1; done
  "$bin/landing" --server "$url" eval "$set_dir" --modes model --window 1 \
    --out "$out/service-$round" > "$out/service-$round.log" 2>&1 || true
  kill "$server"
  wait "$server" || true
  read -r trip own < <(p50 "$out/service-$round/results.json")
  python=$("$py" "$here/pipeline.py" "$root/models/rooftop-segmentation.onnx" "$set_dir"/*.mcap \
    --json "$out/python-$round.json" | tee "$out/python-$round.log" | sed -E 's/.*p50 ([0-9.]+) ms.*/\1/')
  echo "$round      $trip                    $own                $python"
done
