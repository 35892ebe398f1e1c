#!/usr/bin/env python3
"""Writes a dataset's `manifest.jsonl`: every image once, and each image that holds a hard
example of a class (at least --min-pixels of it, its mean colour within --distance of the
building rooftop's in the same image, Euclidean over 0-255 RGB) --repeat times more.

The hard example this was written for: a tarp on a roof of nearly its own colour, which the
model calls roof (issue 42; MODEL_CARD.md, "The tarp fine-tune"). `train.py` reads the
manifest's pairs (`seg/data.py` prefers `manifest.jsonl` to the simulator's `manifest.json`),
and each epoch is a permutation of them, so a repeated image is simply seen more often.

Example (the shipped model's data):
  .venvs/train/bin/python models/training/hard_examples.py /work/data/train2 \
      --class-id 13 --min-pixels 100 --distance 30 --repeat 3
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from safety import ROOFTOP  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data", type=Path, help="a `landing-sim dataset` directory (manifest.csv)")
    p.add_argument("--class-id", type=int, default=13, help="SemanticClass id (13: tarp)")
    p.add_argument("--min-pixels", type=int, default=100)
    p.add_argument("--distance", type=float, default=30.0,
                   help="largest colour distance from the rooftop (0-255 RGB) of a hard example")
    p.add_argument("--repeat", type=int, default=3, help="extra copies of each hard example")
    args = p.parse_args()

    with open(args.data / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    entries, hard, holding = [], 0, 0
    for row in rows:
        entry = {"image": row["image"], "label": row["label"]}
        entries.append(entry)
        labels = np.asarray(Image.open(args.data / row["label"]))
        target, roof = labels == args.class_id, labels == ROOFTOP
        if target.sum() < args.min_pixels or roof.sum() < args.min_pixels:
            continue
        holding += 1
        rgb = np.asarray(Image.open(args.data / row["image"]).convert("RGB"), dtype=np.float32)
        if np.linalg.norm(rgb[target].mean(0) - rgb[roof].mean(0)) <= args.distance:
            hard += 1
            entries.extend([entry] * args.repeat)
    with open(args.data / "manifest.jsonl", "w") as f:
        f.writelines(json.dumps(e) + "\n" for e in entries)
    print(f"{len(rows)} images, {holding} hold class {args.class_id} beside rooftop, {hard} hard "
          f"(within {args.distance}); {len(entries)} entries in {args.data / 'manifest.jsonl'}")


if __name__ == "__main__":
    main()
