#!/usr/bin/env python3
"""Static INT8 quantization of an exported model with ONNX Runtime's own tooling: QDQ format,
int8 weights (per channel) and activations, calibrated on simulator images of the *training*
worlds (never the test worlds the model card scores on).

The graph's ArgMax and the uint8 cast stay in float (they are not quantizable ops); the input
is the same normalised float tensor, so the service runs the result unchanged.

Example:
  cargo run --release -p landing-sim -- dataset --seed 5 --images 200 --split train \
      --out /tmp/calib --width 256 --height 192
  .venvs/train/bin/python models/training/quantize.py models/rooftop-segmentation.onnx \
      --calibration /tmp/calib --out /tmp/rooftop-segmentation-int8.onnx
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import onnx
from onnxruntime.quantization import (CalibrationDataReader, CalibrationMethod, QuantFormat,
                                      QuantType, quantize_static)
from onnxruntime.quantization.shape_inference import quant_pre_process

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seg.data import load_split, to_input  # noqa: E402


class Images(CalibrationDataReader):
    """The calibration images, one at a time, at the model's input size."""

    def __init__(self, root: str, limit: int, size: tuple[int, int]):
        images, _ = load_split(root, limit=limit, size=size)
        self.batches = iter([{"image": to_input(images[i:i + 1].copy()).numpy()}
                             for i in range(images.shape[0])])

    def get_next(self):
        return next(self.batches, None)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("--calibration", required=True, help="dataset directory (training worlds)")
    ap.add_argument("--images", type=int, default=200)
    ap.add_argument("--method", choices=["minmax", "entropy", "percentile"], default="percentile")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    meta = {p.key: p.value for p in onnx.load(args.model).metadata_props}
    size = (int(meta.get("input_width", 256)), int(meta.get("input_height", 192)))
    pre = Path(args.out).with_suffix(".pre.onnx")
    quant_pre_process(args.model, str(pre))
    method = {"minmax": CalibrationMethod.MinMax, "entropy": CalibrationMethod.Entropy,
              "percentile": CalibrationMethod.Percentile}[args.method]
    quantize_static(
        str(pre), args.out, Images(args.calibration, args.images, size),
        quant_format=QuantFormat.QDQ, activation_type=QuantType.QInt8, weight_type=QuantType.QInt8,
        per_channel=True, calibrate_method=method,
    )
    pre.unlink(missing_ok=True)
    quantized = onnx.load(args.out)
    del quantized.metadata_props[:]
    for k, v in {**meta, "quantization": f"static int8 QDQ, per-channel weights, {args.method} "
                                         f"calibration on {args.images} training-world images"}.items():
        quantized.metadata_props.add(key=k, value=v)
    onnx.save(quantized, args.out)
    print(f"wrote {args.out} ({Path(args.out).stat().st_size / 1024:.0f} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
