#!/usr/bin/env python3
"""Exports a checkpoint to ONNX, with argmax and the uint8 cast inside the graph, and checks the
exported model against PyTorch (parity: the class ids must agree on ≥ 99.9 % of pixels; they
differ only where two logits tie within float rounding).

Graph: input `image` float32 [1, 3, H, W] (normalised RGB, dynamic H and W) -> output `classes`
uint8 [1, H, W] (SemanticClass ids 1..14). Opset 18. Metadata: name, arch, input_width,
input_height, mean, std, classes.

Example:
  .venvs/train/bin/python models/training/export.py models/training/runs/mobilenet_fcn8s.pt \
      --out models/rooftop-segmentation.onnx --check-data perception/tests/data
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seg.data import load_split, to_input  # noqa: E402
from seg.models import CLASS_NAMES, MEAN, STD, ExportWrapper, build  # noqa: E402

OPSET = 18


def load_checkpoint(path: str | Path):
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    net = build(ckpt["arch"], ckpt["width"])
    net.load_state_dict(ckpt["state_dict"])
    net.eval()
    return net, ckpt


def export(net, ckpt, out: Path, name: str) -> None:
    wrapper = ExportWrapper(net).eval()
    w, h = ckpt["input_size"]
    example = torch.zeros(1, 3, h, w)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp.onnx")
    # The TorchScript exporter is deprecated but gives a plain, well-optimised graph with dynamic
    # H and W and no onnxscript dependency; its deprecation warning is noise here.
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    torch.onnx.export(
        wrapper,
        (example,),
        str(tmp),
        input_names=["image"],
        output_names=["classes"],
        opset_version=OPSET,
        dynamo=False,
        dynamic_axes={"image": {2: "height", 3: "width"}, "classes": {1: "height", 2: "width"}},
        do_constant_folding=True,
    )
    model = onnx.load(str(tmp))
    meta = {
        "name": name,
        "arch": ckpt["arch"],
        "width_multiplier": str(ckpt["width"]),
        "input_width": str(w),
        "input_height": str(h),
        "mean": json.dumps(list(MEAN)),
        "std": json.dumps(list(STD)),
        "classes": json.dumps(CLASS_NAMES),
        "training": json.dumps(ckpt.get("training", {})),
    }
    del model.metadata_props[:]
    for k, v in meta.items():
        model.metadata_props.add(key=k, value=v)
    model.producer_name = "landing models/training/export.py"
    model.doc_string = "Rooftop semantic segmentation; see models/MODEL_CARD.md"
    onnx.checker.check_model(model)
    onnx.save(model, str(out))
    tmp.unlink(missing_ok=True)


def parity(net, onnx_path: Path, inputs: torch.Tensor) -> dict:
    sess = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    agree = total = 0
    with torch.no_grad():
        for i in range(inputs.shape[0]):
            x = inputs[i:i + 1]
            ref = (net(x).argmax(1) + 1).to(torch.uint8).numpy()
            got = sess.run(None, {"image": x.numpy()})[0]
            if got.shape != ref.shape or got.dtype != np.uint8:
                raise SystemExit(f"parity: shape/dtype {got.shape} {got.dtype} vs {ref.shape} uint8")
            agree += int((got == ref).sum())
            total += ref.size
    return {"images": int(inputs.shape[0]), "pixel_agreement": agree / total}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoint")
    p.add_argument("--out", required=True)
    p.add_argument("--name", help="model name in the metadata (default: the arch)")
    p.add_argument("--check-data", help="dataset dir whose images drive the parity check "
                                        "(default: random inputs)")
    p.add_argument("--check-images", type=int, default=4)
    p.add_argument("--min-agreement", type=float, default=0.999)
    args = p.parse_args(argv)

    torch.set_num_threads(2)
    net, ckpt = load_checkpoint(args.checkpoint)
    out = Path(args.out)
    export(net, ckpt, out, args.name or ckpt["arch"])

    w, h = ckpt["input_size"]
    if args.check_data:
        images, _ = load_split(args.check_data, limit=args.check_images, size=(w, h))
        inputs = to_input(images)
    else:
        inputs = torch.randn(args.check_images, 3, h, w, generator=torch.Generator().manual_seed(0))
    result = parity(net, out, inputs)
    # A second size proves the dynamic height and width.
    odd = torch.randn(1, 3, 240, 320, generator=torch.Generator().manual_seed(1))
    result_odd = parity(net, out, odd)
    size_kb = out.stat().st_size / 1024
    print(json.dumps({"onnx": str(out), "size_kb": round(size_kb, 1), "parity": result,
                      "parity_320x240": result_odd}))
    worst = min(result["pixel_agreement"], result_odd["pixel_agreement"])
    if worst < args.min_agreement:
        print(f"PARITY FAILED: agreement {worst:.5f} < {args.min_agreement}", file=sys.stderr)
        return 1
    print("parity ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
