#!/usr/bin/env python3
"""Evaluates exported ONNX models on a test dataset through ONNX Runtime (exactly what ships) and
writes the model card's tables: per-class IoU (like the paper's Table I) and CPU latency (like its
Table II, ONNX Runtime with 1 and 2 intra-op threads, spinning off).

IoU: over all test pixels, per class c: TP / (TP + FP + FN); pixels labelled 0 (unknown) are
ignored; classes absent from both truth and prediction are N/A; the mean is over the classes
with an IoU. The images are segmented at their own size, as the camera renders them and the
service's first input size takes them (the fresh sets: 320x240). `--size WxH` resizes them first
(bilinear images, nearest labels): a downscaled render is blurrier than one rendered at that
size, and the shipped model loses 0.13 mean IoU to it (0.713 -> 0.580 on the fresh set 8873).

Example:
  .venvs/train/bin/python models/training/evaluate.py --test /work/data/test \
      --model "MobileNet + FCN8s=models/rooftop-segmentation.onnx" \
      --json models/training/results/eval.json --markdown models/training/results/tables.md
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seg.data import load_split, to_input  # noqa: E402
from seg.models import CLASS_NAMES, NUM_CLASSES  # noqa: E402


def session(path: str, threads: int) -> ort.InferenceSession:
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def confusion(sess: ort.InferenceSession, images: np.ndarray, labels: np.ndarray) -> np.ndarray:
    conf = np.zeros((NUM_CLASSES, NUM_CLASSES), dtype=np.int64)
    for i in range(images.shape[0]):
        x = to_input(images[i:i + 1]).numpy()
        pred = sess.run(None, {"image": x})[0][0]
        truth = labels[i]
        keep = truth != 0
        conf += np.bincount(truth[keep].astype(np.int64) * NUM_CLASSES + pred[keep],
                            minlength=NUM_CLASSES * NUM_CLASSES).reshape(NUM_CLASSES, NUM_CLASSES)
    return conf


def iou_from_confusion(conf: np.ndarray) -> dict:
    per_class = {}
    for c in range(1, NUM_CLASSES):
        tp = conf[c, c]
        union = conf[c, 1:].sum() + conf[1:, c].sum() - tp
        per_class[CLASS_NAMES[c]] = None if union == 0 else float(tp / union)
    vals = [v for v in per_class.values() if v is not None]
    truth_pixels = {CLASS_NAMES[c]: int(conf[c, 1:].sum()) for c in range(1, NUM_CLASSES)}
    return {
        "per_class": per_class,
        "mean_iou": float(np.mean(vals)) if vals else 0.0,
        "pixel_accuracy": float(np.trace(conf[1:, 1:]) / max(conf[1:, 1:].sum(), 1)),
        "truth_pixels": truth_pixels,
    }


def latency(path: str, threads: int, w: int, h: int, runs: int) -> dict:
    sess = session(path, threads)
    x = np.random.default_rng(0).standard_normal((1, 3, h, w)).astype(np.float32)
    for _ in range(5):
        sess.run(None, {"image": x})
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        sess.run(None, {"image": x})
        times.append((time.perf_counter() - t) * 1e3)
    return {"median_ms": float(np.median(times)), "p90_ms": float(np.percentile(times, 90))}


def markdown(results: list[dict], sizes: list[tuple[int, int]]) -> str:
    short = ["sky", "ground", "wall", "rooftop", "entrance", "skylight", "vents", "ac-unit",
             "seating", "ducts", "water tower", "chimney", "tarp", "vegetation"]
    lines = ["| model | " + " | ".join(short) + " | mean IoU | pixel acc. |",
             "|---|" + "---|" * (len(short) + 2)]
    for r in results:
        cells = [("N/A" if v is None else f"{v:.2f}") for v in r["iou"]["per_class"].values()]
        lines.append(f"| {r['name']} | " + " | ".join(cells)
                     + f" | **{r['iou']['mean_iou']:.3f}** | {r['iou']['pixel_accuracy']:.3f} |")
    lines.append("")
    head = "| model | params | size | mIoU | " + " | ".join(
        f"{w}×{h} 1 thread (ms) | {w}×{h} 2 threads (ms)" for w, h in sizes) + " |"
    lines += [head, "|---|---|---|---|" + "---|---|" * len(sizes)]
    for r in results:
        cells = []
        for w, h in sizes:
            for t in (1, 2):
                cells.append(f"{r['latency'][f'{w}x{h}'][str(t)]['median_ms']:.2f}")
        lines.append(f"| {r['name']} | {r.get('params', '')} | {r['size_kb']:.0f} kB | "
                     f"{r['iou']['mean_iou']:.3f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--test", required=True, help="test dataset directory")
    p.add_argument("--model", action="append", required=True, help="NAME=path.onnx (repeatable)")
    p.add_argument("--limit", type=int, help="only the first N test images")
    p.add_argument("--latency-runs", type=int, default=50)
    p.add_argument("--latency-size", action="append", default=None,
                   help="WxH for the latency table (repeatable; default 320x240 and the images' size)")
    p.add_argument("--json")
    p.add_argument("--markdown")
    p.add_argument("--threads", type=int, default=2, help="threads for the IoU pass")
    p.add_argument("--size", help="resize the test images to WxH first (default: their own size)")
    args = p.parse_args(argv)

    results = []
    resize = tuple(int(v) for v in args.size.split("x")) if args.size else None
    images, labels = load_split(args.test, limit=args.limit, size=resize)
    h, w = (int(v) for v in images.shape[1:3])
    sizes = [tuple(int(v) for v in s.split("x")) for s in (args.latency_size or ["320x240"])]
    for spec in args.model:
        name, path = spec.split("=", 1)
        sess = session(path, args.threads)
        meta = sess.get_modelmeta().custom_metadata_map
        t = time.time()
        conf = confusion(sess, images, labels)
        res = {"name": name, "path": path, "input_size": [w, h], "test_images": int(images.shape[0]),
               "iou": iou_from_confusion(conf), "size_kb": Path(path).stat().st_size / 1024,
               "training": json.loads(meta.get("training", "{}")), "latency": {}}
        all_sizes = sizes + ([(w, h)] if (w, h) not in sizes else [])
        for lw, lh in all_sizes:
            res["latency"][f"{lw}x{lh}"] = {str(th): latency(path, th, lw, lh, args.latency_runs)
                                           for th in (1, 2)}
        print(json.dumps({"name": name, "mean_iou": res["iou"]["mean_iou"],
                          "rooftop_iou": res["iou"]["per_class"]["building rooftop"],
                          "eval_s": round(time.time() - t, 1), "latency": res["latency"]}), flush=True)
        results.append(res)
    all_sizes = sizes[:]
    for r in results:
        s = tuple(r["input_size"])
        if s not in all_sizes:
            all_sizes.append(s)
    md = markdown(results, [s for s in all_sizes if all(f"{s[0]}x{s[1]}" in r["latency"] for r in results)])
    print(md)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(results, indent=1) + "\n")
    if args.markdown:
        Path(args.markdown).parent.mkdir(parents=True, exist_ok=True)
        Path(args.markdown).write_text(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
