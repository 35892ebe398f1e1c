#!/usr/bin/env bash
# Starts the long training run (issue 42) in the background, or resumes it from its last
# checkpoint; does nothing while it runs. Idempotent: run it at the start of every session.
#
#   bash models/training/long-run.sh          # start / resume; prints what it did
#   tail -f /work/runs/long/train.log          # progress (step, loss, lr, images/s)
#   cat /work/runs/long/model.candidates.json  # the best checkpoints by the pixel rule
#   kill -TERM "$(cat /work/runs/long/pid)"    # stop: checkpoints, then exits
#
# The run survives the shell (setsid nohup), runs under nice -n 19 on one torch thread, and
# checkpoints atomically every 5 minutes and on SIGTERM/SIGINT; after a kill (even SIGKILL) the
# next invocation resumes from the last checkpoint: same weights, optimizer, schedule step, RNG
# states and position in the data order. The schedule (warm-up + cosine over TOTAL_STEPS) does
# not depend on how many sessions it takes.
#
# The data is made once, outside the repository (3.3 GB; about 25 min on one core):
#   target/release/landing-sim dataset --seed 1 --images 30000 --split train \
#       --out /work/data/train30k --width 256 --height 192
#   target/release/landing-sim dataset --seed 2301 --images 200 --split test \
#       --out /work/data/dev2301 --width 320 --height 240
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
run=${RUN_DIR:-/work/runs/long}
data=${DATA:-/work/data/train30k}
dev=${DEV:-/work/data/dev2301}
arch=${ARCH:-mobilenet_fcn4s}
total_steps=${TOTAL_STEPS:-120000}

for d in "$data" "$dev"; do
  [ -f "$d/manifest.json" ] || { echo "long-run: no dataset at $d (see the commands at the top of $0)" >&2; exit 1; }
done
mkdir -p "$run"
exec 8> "$run/run.lock"
if ! flock -n 8; then
  echo "long-run: already running (pid $(cat "$run/pid" 2>/dev/null || echo '?')); log: $run/train.log"
  exit 0
fi
python=$(bash "$root/scripts/python-env.sh" train "$root/models/training/requirements.txt")
# The training process inherits the lock (fd 8) and holds it for as long as it lives.
setsid nohup nice -n 19 "$python" "$root/models/training/train.py" --resume \
  --arch "$arch" --train "$data" --init-onnx "$root/models/rooftop-segmentation.onnx" \
  --batch 8 --lr 1e-3 --balance 0.5 --seed 42 --threads 1 --total-steps "$total_steps" \
  --minutes 100000 --checkpoint-minutes 5 --val "$dev" --val-minutes 30 --keep-best 3 \
  --out "$run/model.pt" --log "$run/train.log" --val-log "$run/val.jsonl" \
  >> "$run/stdout.log" 2>&1 < /dev/null &
echo $! > "$run/pid"
echo "long-run: started pid $! ($arch, $total_steps steps); log: $run/train.log"
