#!/usr/bin/env bash
# CI smoke test of the training code: a few training steps on the committed simulator frames
# (perception/tests/data), an exact resume, ONNX export, and the parity check of ONNX Runtime
# against PyTorch. Takes about two minutes on 2 cores. Writes only under a temporary directory.
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
# An FCN4s grows out of an exported FCN8s (its /4 scores start at zero).
"$python" "$root/models/training/train.py" --arch mobilenet_fcn4s --train "$data" --size 128x96 \
  --steps 1 --batch 4 --threads 2 --init-onnx "$tmp/mobilenet_fcn8s.onnx" --out "$tmp/grown.pt"
# Resuming is exact: 3 + 3 steps in two sessions give the weights of 6 in one (an FCN4s
# warm-started from the shipped FCN4s), and the FCN4s exports with parity.
resume=(--arch mobilenet_fcn4s --train "$data" --size 128x96 --batch 4 --total-steps 6 --threads 2
        --init-onnx "$root/models/rooftop-segmentation.onnx")
"$python" "$root/models/training/train.py" "${resume[@]}" --out "$tmp/once.pt"
"$python" "$root/models/training/train.py" "${resume[@]}" --steps 3 --out "$tmp/twice.pt"
"$python" "$root/models/training/train.py" "${resume[@]}" --resume --out "$tmp/twice.pt"
"$python" - "$tmp/once.pt" "$tmp/twice.pt" <<'PY'
import sys, torch
a, b = (torch.load(p, map_location="cpu", weights_only=False) for p in sys.argv[1:3])
assert a["training"]["steps"] == b["training"]["steps"] == 6, "steps"
assert b["training"]["sessions"] == 2, "the second run did not resume"
diff = max((a["state_dict"][k].float() - b["state_dict"][k].float()).abs().max().item() for k in a["state_dict"])
assert diff == 0.0, f"resumed weights differ by {diff}"
print("resume ok: 3 + 3 steps == 6 steps")
PY
"$python" "$root/models/training/export.py" "$tmp/once.pt" --out "$tmp/once.onnx" --check-data "$data"
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
echo "smoke: train + resume + export + parity passed"
