#!/usr/bin/env python3
"""Trains one segmentation network on a simulator dataset, from scratch, on the CPU.

Training runs for a wall-clock budget (--minutes) or a number of epochs, whichever ends first; the
learning rate follows a warm-up then a cosine decay over that budget, so a short budget still ends
annealed. The last weights are saved (with --val, the best on the validation subset is kept too).

Example (the shipped model):
  .venvs/train/bin/python models/training/train.py --arch mobilenet_fcn8s \
      --train /work/data/train --minutes 40 --out models/training/runs/mobilenet_fcn8s.pt
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seg.data import load_split, to_input, to_target  # noqa: E402
from seg.warm_start import load_onnx_weights, onnx_training  # noqa: E402
from seg.models import ARCHITECTURES, NUM_OUTPUTS, build, count_parameters  # noqa: E402


def parse_size(text: str | None):
    if not text:
        return None
    w, h = text.lower().split("x")
    return int(w), int(h)


def class_weights(labels: np.ndarray, power: float = 0.3) -> torch.Tensor:
    """Softened median-frequency balancing over the 14 predicted classes: (median / freq)^power,
    clipped to [0.3, 3], so rare obstacles count more without starving the large classes."""
    counts = np.bincount(labels.reshape(-1), minlength=NUM_OUTPUTS + 1)[1:].astype(np.float64)
    freq = counts / max(counts.sum(), 1.0)
    present = freq > 0
    w = np.ones(NUM_OUTPUTS)
    if present.any():
        med = np.median(freq[present])
        w[present] = (med / freq[present]) ** power
    return torch.tensor(np.clip(w, 0.3, 3.0), dtype=torch.float32)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--arch", choices=ARCHITECTURES, default="mobilenet_fcn8s")
    p.add_argument("--width", type=float, default=0.5, help="backbone width multiplier")
    p.add_argument("--train", required=True, help="dataset directory (landing-sim dataset --split train)")
    p.add_argument("--size", help="train at WxH (resizes the data), default: the data's size")
    p.add_argument("--limit", type=int, help="use only the first N training images")
    p.add_argument("--crop", help="train on random WxH crops (cheaper steps; the network is fully "
                                  "convolutional and is evaluated on whole images)")
    p.add_argument("--minutes", type=float, default=30.0, help="wall-clock training budget")
    p.add_argument("--epochs", type=int, default=1000, help="at most this many epochs")
    p.add_argument("--steps", type=int, help="at most this many steps (smoke tests)")
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--lr", type=float, default=3e-3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--init", help="start from this checkpoint's weights (fine-tuning) instead of "
                                  "from scratch")
    p.add_argument("--init-onnx", help="start from the weights of an exported model (e.g. the "
                                       "shipped one) of the same architecture and width")
    p.add_argument("--balance", type=float, default=0.3,
                   help="class weight exponent: (median / freq)^balance, 0 = unweighted")
    p.add_argument("--out", required=True, help="checkpoint path (.pt)")
    args = p.parse_args(argv)

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)

    t_load = time.time()
    images, labels = load_split(args.train, limit=args.limit, size=parse_size(args.size))
    n, h, w, _ = images.shape
    print(f"loaded {n} images {w}x{h} from {args.train} in {time.time() - t_load:.1f}s", flush=True)
    crop = parse_size(args.crop)
    if crop is not None and (crop[0] > w or crop[1] > h):
        raise SystemExit(f"--crop {args.crop} is larger than the {w}x{h} images")
    weights = class_weights(labels, args.balance)
    print("class weights:", [round(float(x), 2) for x in weights], flush=True)

    net = build(args.arch, args.width)
    prior = None
    if args.init:
        prior = torch.load(args.init, map_location="cpu", weights_only=False)
        if prior["arch"] != args.arch or prior["width"] != args.width:
            raise SystemExit(f"--init {args.init} is {prior['arch']} x{prior['width']}")
        net.load_state_dict(prior["state_dict"])
    if args.init_onnx:
        calibration = to_input(images[rng.choice(n, size=min(n, 32), replace=False)])
        load_onnx_weights(net, args.init_onnx, calibration)
        print(f"initialised from {args.init_onnx}", flush=True)
    print(f"{args.arch}: {count_parameters(net)} parameters", flush=True)
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=1e-4)

    budget_s = args.minutes * 60.0
    steps_per_epoch = max(1, n // args.batch)
    max_steps = args.epochs * steps_per_epoch
    if args.steps:
        max_steps = min(max_steps, args.steps)
    warmup = 0.03

    def lr_at(progress: float) -> float:
        if progress < warmup:
            return args.lr * (0.1 + 0.9 * progress / warmup)
        q = (progress - warmup) / (1 - warmup)
        return args.lr * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(q, 1.0))))

    start = time.time()
    step = 0
    epoch = 0
    seen = 0
    done = False
    loss_avg = None
    while not done:
        epoch += 1
        order = rng.permutation(n)
        for b in range(steps_per_epoch):
            elapsed = time.time() - start
            progress = max(elapsed / budget_s, step / max_steps)
            if progress >= 1.0:
                done = True
                break
            for g in opt.param_groups:
                g["lr"] = lr_at(progress)
            idx = order[b * args.batch:(b + 1) * args.batch]
            if crop is not None:
                cw, ch = crop
                x0 = int(rng.integers(0, w - cw + 1))
                y0 = int(rng.integers(0, h - ch + 1))
                x = to_input(images[idx, y0:y0 + ch, x0:x0 + cw])
                y = to_target(labels[idx, y0:y0 + ch, x0:x0 + cw])
            else:
                x = to_input(images[idx])
                y = to_target(labels[idx])
            # Augmentation: horizontal flips and per-image brightness/contrast.
            flip = torch.from_numpy(rng.random(len(idx)) < 0.5)
            x[flip] = x[flip].flip(-1)
            y[flip] = y[flip].flip(-1)
            gain = torch.from_numpy(rng.uniform(0.8, 1.2, (len(idx), 1, 1, 1))).float()
            bias = torch.from_numpy(rng.uniform(-0.2, 0.2, (len(idx), 1, 1, 1))).float()
            x = x * gain + bias

            net.train()
            logits = net(x)
            loss = F.cross_entropy(logits, y, weight=weights, ignore_index=255)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step += 1
            seen += len(idx)
            loss_avg = loss.item() if loss_avg is None else 0.95 * loss_avg + 0.05 * loss.item()
            if step % 20 == 0 or step == 1:
                rate = seen / max(time.time() - start, 1e-6)
                print(f"epoch {epoch} step {step} loss {loss_avg:.4f} lr {lr_at(progress):.2e} "
                      f"{rate:.1f} img/s elapsed {time.time() - start:.0f}s", flush=True)
        if step >= max_steps:
            done = True

    train_s = time.time() - start
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    ckpt = {
        "arch": args.arch,
        "width": args.width,
        "state_dict": net.state_dict(),
        "input_size": [w, h],
        "training": {
            "dataset": str(args.train),
            "images": n,
            "epochs": round(seen / n, 2),
            "steps": step,
            "batch": args.batch,
            "crop": args.crop,
            "minutes": round(train_s / 60.0, 1),
            "threads": args.threads,
            "lr": args.lr,
            "final_loss": loss_avg,
            "command": " ".join([os.path.relpath(sys.argv[0])] + (argv or sys.argv[1:])),
            "torch": torch.__version__,
            "init": args.init or args.init_onnx,
            "balance": args.balance,
            "previous": prior["training"] if prior else onnx_training(args.init_onnx),
        },
    }
    tmp = out.with_suffix(".tmp")
    torch.save(ckpt, tmp)
    tmp.replace(out)
    print(json.dumps({"saved": str(out), **ckpt["training"]}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
