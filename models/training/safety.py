#!/usr/bin/env python3
"""The model card's safety table: per true class, the share of its pixels the shipped model calls
landable (building rooftop), at each input size the service runs and under the service's
two-size guard (a pixel is landable only where every size says so).

A non-rooftop pixel called landable is what can become an unsafe landing site: an obstacle on
the roof (classes 5-14), or the ground or a wall beside it (2, 3). Pixels labelled 0 (unknown)
are ignored. Images are taken at the camera's own size (the service's camera: 320x240); each
input size resizes the image to it (bilinear, as `landing_perception::preprocess` does) and the
mask back to the camera's size (nearest), where the guard combines them. The service stretches
each mask over the camera's pixels in the same way when it projects the points.

Example:
  cargo run --release -p landing-sim -- dataset --seed 4242 --images 300 --split test \
      --out /tmp/safety-test --width 320 --height 240
  .venvs/train/bin/python models/training/safety.py --test /tmp/safety-test \
      --model models/rooftop-segmentation.onnx --sizes 320x240,256x192 --json /tmp/safety.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import onnxruntime as ort
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seg.data import load_split, to_input  # noqa: E402
from seg.models import CLASS_NAMES, NUM_CLASSES  # noqa: E402

ROOFTOP = 4
# The classes whose pixels a landing site must keep off: the roof's obstacles.
ROOF_OBSTACLES = range(5, NUM_CLASSES)


def session(path: str) -> ort.InferenceSession:
    """The model on one CPU thread."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def predict(sess, image: np.ndarray, w: int, h: int) -> np.ndarray:
    """The model's classes at input size (w, h), resized back to the image's size (nearest)."""
    height, width = image.shape[:2]
    resized = np.asarray(Image.fromarray(image).resize((w, h), Image.BILINEAR))
    (classes,) = sess.run(["classes"], {"image": to_input(resized[None].copy()).numpy()})
    classes = classes[0]
    if (w, h) != (width, height):
        classes = np.asarray(Image.fromarray(classes).resize((width, height), Image.NEAREST))
    return classes


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--test", required=True, help="dataset directory (landing-sim dataset)")
    ap.add_argument("--model", required=True)
    ap.add_argument("--sizes", default="320x240,256x192", help="input sizes, as the service's input_sizes")
    ap.add_argument("--limit", type=int)
    ap.add_argument("--json")
    args = ap.parse_args()
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    sess = session(args.model)
    images, labels = load_split(args.test, limit=args.limit)
    columns = [f"{w}x{h}" for w, h in sizes] + (["guard"] if len(sizes) > 1 else [])
    landable = {c: np.zeros(NUM_CLASSES, dtype=np.int64) for c in columns}
    truth = np.zeros(NUM_CLASSES, dtype=np.int64)
    for image, label in zip(images, labels):
        keep = label != 0
        truth += np.bincount(label[keep], minlength=NUM_CLASSES)
        masks = []
        for (w, h), column in zip(sizes, columns):
            roof = predict(sess, image, w, h) == ROOFTOP
            masks.append(roof)
            landable[column] += np.bincount(label[keep & roof], minlength=NUM_CLASSES)
        if len(sizes) > 1:
            guard = np.logical_and.reduce(masks)
            landable["guard"] += np.bincount(label[keep & guard], minlength=NUM_CLASSES)

    def share(column: str, classes) -> float | None:
        n = sum(int(truth[c]) for c in classes)
        return None if n == 0 else sum(int(landable[column][c]) for c in classes) / n

    rows = [(CLASS_NAMES[c], [c]) for c in range(1, NUM_CLASSES)]
    rows.append(("roof obstacles (5-14)", list(ROOF_OBSTACLES)))
    rows.append(("everything but rooftop", [c for c in range(1, NUM_CLASSES) if c != ROOFTOP]))
    result = {
        "model": args.model,
        "test": args.test,
        "images": int(images.shape[0]),
        "image_size": [int(images.shape[2]), int(images.shape[1])],
        "truth_pixels": {CLASS_NAMES[c]: int(truth[c]) for c in range(1, NUM_CLASSES)},
        "landable_share": {name: {col: share(col, cls) for col in columns} for name, cls in rows},
    }
    fmt = lambda v: "N/A" if v is None else f"{100 * v:.1f} %"  # noqa: E731
    print(f"| true class | pixels | " + " | ".join(f"called landable, {c}" for c in columns) + " |")
    print("|---|---|" + "---|" * len(columns))
    for name, cls in rows:
        n = sum(int(truth[c]) for c in cls)
        print(f"| {name} | {n:,} | " + " | ".join(fmt(share(col, cls)) for col in columns) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
