#!/usr/bin/env bash
# Load-test matrix: `landing loadtest` throughput and latency for 1, 2, 4, 8, 16 streams with
# segmentation by the server's model, by the recording's label images sent as class images (a
# drone that segments on board), and off (geometry only), against a release server started
# here. Streams are single-frame (`--single-frame`, the paper's method; `MODE=fused` for the
# default fused streams). Prints one Markdown table row per run; the JSON summaries go to $OUT_DIR.
#
#   cargo build --release -p landing-server -p landing-cli
#   cli/scripts/loadtest-matrix.sh [DURATION_S] [STREAMS...]
set -euo pipefail
cd "$(dirname "$0")/../.."
DURATION=${1:-10}
case "${MODE:-single-frame}" in
  single-frame) mode_flag=(--single-frame) ;;
  fused) mode_flag=() ;;
  *) echo "MODE is single-frame or fused, not $MODE" >&2; exit 2 ;;
esac
shift || true
STREAMS=${*:-1 2 4 8 16}
PORT=${PORT:-50081}
OUT_DIR=${OUT_DIR:-target/loadtest}
WINDOW=${WINDOW:-2}
mkdir -p "$OUT_DIR"
. scripts/lib.sh
if [ -z "${SERVER:-}" ] || [ -z "${LANDING:-}" ]; then bin=$(release_bin_dir); fi  # honours CARGO_TARGET_DIR
SERVER=${SERVER:-$bin/landing-server}
LANDING=${LANDING:-$bin/landing}
REC=samples/rooftops.mcap

"$SERVER" serve --listen "127.0.0.1:$PORT" --metrics-listen "" >"$OUT_DIR/server.log" 2>&1 &
SERVER_PID=$!
trap 'kill -TERM $SERVER_PID 2>/dev/null; wait $SERVER_PID 2>/dev/null || true' EXIT
for _ in $(seq 1 100); do
  "$LANDING" --server "http://127.0.0.1:$PORT" info >/dev/null 2>&1 && break
  sleep 0.2
done

echo "| segmentation | streams | frames/s | p50 ms | p95 ms | p99 ms | outcomes | exactly once |"
echo "|---|---:|---:|---:|---:|---:|---|---|"
for seg in model class-image none; do
  for n in $STREAMS; do
    json="$OUT_DIR/$seg-$n.json"
    "$LANDING" --server "http://127.0.0.1:$PORT" loadtest "$REC" --streams "$n" --duration "$DURATION" \
      --window "$WINDOW" --segmentation "$seg" "${mode_flag[@]}" --json >"$json" || true
    python3 - "$json" "$seg" "$n" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
l = r["latency_ms"]
outcomes = ", ".join(f"{k} {v}" for k, v in sorted(r["outcomes"].items()))
once = "yes" if r["sent"] == r["answered"] and r["unanswered"] == 0 and r["unexpected"] == 0 else "NO"
print(f"| {sys.argv[2]} | {sys.argv[3]} | {r['throughput_fps']:.1f} | {l['p50']:.1f} | {l['p95']:.1f} | {l['p99']:.1f} | {outcomes} | {once} |")
PY
  done
done
