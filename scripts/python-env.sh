#!/usr/bin/env bash
# Makes (or refreshes) the Python venv <workspace>/.venvs/NAME with the given requirement files
# installed, and prints the absolute path of its python: that path only, on stdout; progress goes
# to stderr. Each job has its own venv so that a command installs only what it uses: the demo needs
# no Python, the cross-language checks a few small wheels, training PyTorch (gigabytes).
#
# Idempotent and cheap when done: pip runs only when the requirement files' combined sha256
# differs from the stamp left in the venv by the last successful install.
#
# Usage: py=$(bash scripts/python-env.sh NAME REQUIREMENTS...)
#   checks  sim/tests/python/requirements.txt client/examples/python/requirements.txt (scripts/test.sh)
#   train   models/training/requirements.txt (models/training/smoke.sh)
#   deploy  deploy/requirements.txt (deploy/check.sh)
# BASE_PYTHON (default python3) is the interpreter a new venv is made from.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 NAME REQUIREMENTS..." >&2
  exit 2
fi
name=$1
shift
case "$name" in
  ''|*[!A-Za-z0-9_.-]*|.*) echo "python-env: bad venv name '$name'" >&2; exit 2 ;;
esac
for r in "$@"; do
  [ -f "$r" ] || { echo "python-env: no requirements file $r" >&2; exit 1; }
done

root=$(cd "$(dirname "$0")/.." && pwd)
venv="$root/.venvs/$name"
py="$venv/bin/python"
mkdir -p "$root/.venvs"
# One installer at a time per venv (two scripts may want the same one at once).
exec 9> "$root/.venvs/$name.lock"
if command -v flock > /dev/null; then flock 9; fi

if [ ! -x "$py" ]; then
  echo "python-env: creating $venv" >&2
  "${BASE_PYTHON:-python3}" -m venv "$venv" >&2
fi
stamp="$venv/.requirements.sha256"
want=$(cat "$@" | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "python-env: installing $* into .venvs/$name" >&2
  args=()
  for r in "$@"; do args+=(-r "$r"); done
  # No wheel cache: the venv is what is kept, and PyTorch's wheels would take gigabytes twice.
  "$py" -m pip install --quiet --disable-pip-version-check --no-cache-dir --upgrade pip >&2
  "$py" -m pip install --quiet --disable-pip-version-check --no-cache-dir "${args[@]}" >&2
  echo "$want" > "$stamp"
fi
echo "$py"
