#!/usr/bin/env bash
# Prepares a fresh machine for building and running the service: the ONNX Runtime library in
# .ort/ (scripts/setup-ort.sh, from the PyPI wheel). Idempotent; cheap when already done.
# Nothing Python is installed here: each command that needs Python makes its own venv under
# .venvs/ with scripts/python-env.sh (scripts/test.sh: checks; models/training/smoke.sh: train;
# deploy/check.sh: deploy), so the demo installs only what it needs.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bash "$root/scripts/setup-ort.sh"
