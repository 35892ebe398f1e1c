#!/usr/bin/env bash
# CI smoke test of the training code: a few training steps on the committed simulator frames
# (perception/tests/data), ONNX export, and the parity check of ONNX Runtime against PyTorch.
# Takes about a minute on 2 cores. Writes only under a temporary directory.
# PYTHON: an interpreter with models/training/requirements.txt; by default the venv .venvs/train,
# made or refreshed here by scripts/python-env.sh (PyTorch: gigabytes the first time).
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
python=${PYTHON:-$(bash "$root/scripts/python-env.sh" train "$root/models/training/requirements.txt")}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
data="$root/perception/tests/data"
for arch in mobilenet_fcn8s shufflenet_unet; do
  "$python" "$root/models/training/train.py" --arch "$arch" --train "$data" --size 128x96 \
    --steps 6 --batch 4 --minutes 2 --out "$tmp/$arch.pt"
  "$python" "$root/models/training/export.py" "$tmp/$arch.pt" --out "$tmp/$arch.onnx" \
    --check-data "$data"
done
# The shipped model loads, has the documented signature, and is still small.
"$python" - "$root/models/rooftop-segmentation.onnx" <<'PY'
import sys, onnx
m = onnx.load(sys.argv[1])
onnx.checker.check_model(m)
meta = {p.key: p.value for p in m.metadata_props}
assert m.graph.input[0].name == "image" and m.graph.output[0].name == "classes", "signature"
assert m.graph.output[0].type.tensor_type.elem_type == onnx.TensorProto.UINT8, "uint8 output"
assert max(o.version for o in m.opset_import if o.domain in ("", "ai.onnx")) >= 17, "opset"
size_mb = len(m.SerializeToString()) / 2**20
assert size_mb < 8, f"shipped model is {size_mb:.1f} MB"
print(f"shipped model ok: {meta.get('name')} {meta.get('input_width')}x{meta.get('input_height')}, {size_mb:.2f} MB")
PY
echo "smoke: train + export + parity passed"
