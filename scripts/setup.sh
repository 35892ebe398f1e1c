#!/usr/bin/env bash
# Prepares a fresh machine: the ONNX Runtime library (from the PyPI wheel) and the Python venv
# used by the training code and the cross-language checks. Idempotent; cheap when already done.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

bash scripts/setup-ort.sh

venv="$root/.venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
stamp="$venv/.requirements.sha256"
reqs=(models/training/requirements.txt client/examples/python/requirements.txt sim/tests/python/requirements.txt deploy/requirements.txt)
present=()
for r in "${reqs[@]}"; do [ -f "$r" ] && present+=("$r"); done
want=$(cat "${present[@]}" | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  "$venv/bin/python" -m pip install --quiet --upgrade pip
  args=()
  for r in "${present[@]}"; do args+=(-r "$r"); done
  "$venv/bin/python" -m pip install --quiet "${args[@]}"
  echo "$want" > "$stamp"
fi
echo "setup: ONNX Runtime in .ort/, Python venv in .venv/"
