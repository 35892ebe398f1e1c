#!/usr/bin/env bash
# Puts the ONNX Runtime shared library at <workspace>/.ort/libonnxruntime.so, taken from the PyPI
# wheel `onnxruntime==1.31.1` (the only place this machine may get it from). `landing-perception`
# loads it at run time (`ORT_DYLIB_PATH` wins over this default location).
#
# Idempotent: does nothing when the library of the right version is already there.
# Usage: scripts/setup-ort.sh            (PYTHON=python3 by default; needs pip and unzip or python)
set -euo pipefail

version="1.31.1"
root=$(cd "$(dirname "$0")/.." && pwd)
dest_dir="$root/.ort"
dest="$dest_dir/libonnxruntime.so"
stamp="$dest_dir/VERSION"
python=${PYTHON:-python3}

if [ -f "$dest" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$version" ]; then
  echo "setup-ort: ONNX Runtime $version already at $dest"
  exit 0
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

echo "setup-ort: downloading the onnxruntime==$version wheel from PyPI"
"$python" -m pip download --quiet --no-deps --only-binary=:all: \
  --dest "$tmp" "onnxruntime==$version"
wheel=$(ls "$tmp"/onnxruntime-"$version"-*.whl | head -n 1)
member="onnxruntime/capi/libonnxruntime.so.$version"

# Extract with Python's zipfile so that `unzip` is not a requirement.
"$python" - "$wheel" "$member" "$tmp/libonnxruntime.so" <<'PY'
import shutil, sys, zipfile
wheel, member, out = sys.argv[1:4]
with zipfile.ZipFile(wheel) as z, z.open(member) as src, open(out, "wb") as dst:
    shutil.copyfileobj(src, dst)
PY

mkdir -p "$dest_dir"
# Move into place atomically so a concurrent reader never sees half a library.
mv "$tmp/libonnxruntime.so" "$dest.partial"
mv "$dest.partial" "$dest"
echo "$version" > "$stamp"
echo "setup-ort: ONNX Runtime $version installed at $dest"
