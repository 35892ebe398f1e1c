#!/usr/bin/env python3
"""Scores an exported segmentation model on the camera frames of simulator recordings at several
input sizes, each alone and fused the way the service fuses them
(`landing_perception::ClassMask::fuse_keeping_obstacles`: a pixel stays landable only where every
size calls it landable; otherwise it takes the first obstacle class, finest size first).

What it reports, against the recordings' `/camera/labels` at the camera's resolution:
- mean IoU over the classes present, and pixel accuracy;
- rooftop precision and recall (what landing depends on: a rooftop pixel that is really an
  obstacle is the dangerous error);
- per obstacle class, the share of its pixels *not* called rooftop (what keeps a safe circle
  off it).

Preprocessing here is PIL's bilinear resize, the Rust service's is `image`'s; masks differ on a
few border pixels. The service's own numbers are in EVALUATION.md (`landing eval`).

Example (the scenario set of EVALUATION.md):
  target/release/landing-sim scenarios --seed 2026 --worlds 6 --buildings 6 --frames 4 \\
      --out eval-full/scenarios
  .venvs/train/bin/python models/training/multiscale.py eval-full/scenarios \\
      --model models/rooftop-segmentation.onnx --sizes 320x240,256x192,160x120
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from evaluate import iou_from_confusion, session  # noqa: E402
from safety import ROOFTOP  # noqa: E402
from seg.models import NUM_CLASSES  # noqa: E402

OBSTACLES = range(5, 14)  # entrance … tarp
NAMES = {5: "entrance", 6: "skylight", 7: "vents", 8: "ac-unit", 9: "seating", 10: "ducts",
         11: "water tower", 12: "chimney", 13: "tarp"}


def frames(path: Path):
    """(camera image, label image) pairs of one recording, in order."""
    images, labels = [], []
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        # Both are foxglove.CompressedImage (PNG), one per frame, in frame order.
        for _, channel, _, message in reader.iter_decoded_messages(
            topics=["/camera/image", "/camera/labels"]
        ):
            if channel.topic == "/camera/image":
                images.append(Image.open(io.BytesIO(message.data)).convert("RGB"))
            else:
                labels.append(np.array(Image.open(io.BytesIO(message.data))))
    return zip(images, labels)


def fuse(masks: list[np.ndarray]) -> np.ndarray:
    """Masks already at one size, finest first: landable only where all agree."""
    fused = masks[0].copy()
    obstacle = lambda m: (m != 0) & (m != ROOFTOP)  # noqa: E731
    for other in masks[1:]:
        take = ~obstacle(fused) & obstacle(other)
        fused[take] = other[take]
    return fused


def scores(confusion: np.ndarray) -> dict:
    """evaluate.py's IoU and pixel accuracy, plus what landing depends on."""
    tp = np.diag(confusion).astype(float)
    iou = iou_from_confusion(confusion)
    return {
        "mean_iou": iou["mean_iou"],
        "pixel_accuracy": iou["pixel_accuracy"],
        "rooftop_precision": float(tp[ROOFTOP] / max(confusion[:, ROOFTOP].sum(), 1)),
        "rooftop_recall": float(tp[ROOFTOP] / max(confusion[ROOFTOP].sum(), 1)),
        "obstacle_not_rooftop": {
            NAMES[c]: float(1 - confusion[c, ROOFTOP] / confusion[c].sum())
            for c in OBSTACLES
            if confusion[c].sum() > 0
        },
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recordings", type=Path, help="folder of .mcap recordings with /camera/labels")
    ap.add_argument("--model", default="models/rooftop-segmentation.onnx")
    ap.add_argument("--sizes", default="320x240,256x192", help="WxH,… finest first")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", type=Path, help="also write the scores here")
    args = ap.parse_args()

    sizes = [tuple(int(v) for v in s.lower().split("x")) for s in args.sizes.split(",")]
    model = session(args.model, args.threads)
    meta = model.get_modelmeta().custom_metadata_map
    mean = np.array(json.loads(meta["mean"]), dtype=np.float32)
    std = np.array(json.loads(meta["std"]), dtype=np.float32)
    input_name = model.get_inputs()[0].name

    fused_names = [f"fused {'+'.join(f'{w}x{h}' for w, h in sizes[:k])}" for k in range(2, len(sizes) + 1)]
    names = [f"{w}x{h}" for w, h in sizes] + fused_names
    confusion = {n: np.zeros((NUM_CLASSES, NUM_CLASSES), np.int64) for n in names}
    recordings = sorted(args.recordings.glob("*.mcap"))
    if not recordings:
        print(f"no .mcap files in {args.recordings}", file=sys.stderr)
        return 2
    count = 0
    for path in recordings:
        for image, labels in frames(path):
            masks = []
            for w, h in sizes:
                x = np.asarray(image.resize((w, h), Image.BILINEAR), dtype=np.float32) / 255.0
                x = ((x - mean) / std).transpose(2, 0, 1)[None].astype(np.float32)
                out = model.run(None, {input_name: x})[0].reshape(h, w).astype(np.uint8)
                masks.append(np.array(Image.fromarray(out).resize(image.size, Image.NEAREST)))
            predictions = masks + [fuse(masks[:k]) for k in range(2, len(sizes) + 1)]
            known = labels > 0
            truth = labels[known].astype(np.int64)
            for name, prediction in zip(names, predictions):
                cells = truth * NUM_CLASSES + prediction[known].astype(np.int64)
                confusion[name] += np.bincount(cells, minlength=NUM_CLASSES**2).reshape(
                    NUM_CLASSES, NUM_CLASSES
                )
            count += 1

    report = {name: scores(c) for name, c in confusion.items()}
    print(f"{count} frames of {len(recordings)} recordings, model {args.model}\n")
    header = "| input | mean IoU | pixel acc. | rooftop precision | rooftop recall | " + " | ".join(
        NAMES[c] for c in OBSTACLES
    ) + " |"
    print(header)
    print("|---" * (header.count("|") - 1) + "|")
    for name, r in report.items():
        cells = [r["obstacle_not_rooftop"].get(NAMES[c]) for c in OBSTACLES]
        print(
            f"| {name} | {r['mean_iou']:.3f} | {r['pixel_accuracy']:.3f} | "
            f"{r['rooftop_precision']:.3f} | {r['rooftop_recall']:.3f} | "
            + " | ".join("-" if v is None else f"{v:.2f}" for v in cells)
            + " |"
        )
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
