#!/usr/bin/env python3
"""Trains one segmentation network on a simulator dataset on the CPU, resumably.

The learning rate follows a warm-up (3 % of the steps) then a cosine decay over `--total-steps`
(default: `--steps`, else `--epochs` passes), so the schedule depends on the step only and a run
split over many sessions follows the same curve as one uninterrupted run. `--minutes` is this
session's wall-clock budget: when it is spent the session checkpoints and stops.

Checkpoints (`--out`) are written atomically (temporary file, fsync, rename) every
`--checkpoint-minutes`, at the end of the session and on SIGTERM/SIGINT. Each holds the weights
(what export.py reads) and the state to resume exactly: optimizer, step, position in the data
order (each epoch's order is a function of --seed and the epoch), the augmentation and dropout
RNG states and the class weights. `--resume` continues from `--out` when it exists (and starts
when it does not); the data, batch, schedule and seed must then be the ones it was started with.

Log: a line every `--log-every` steps (step, loss, lr, images/s) on stdout and appended to
`--log` (default: next to --out, suffix .log).

Validation (`--val DIR`, e.g. 200 development-world images at 320x240): every `--val-minutes`
(at a checkpoint) and at the end of each session, pixel-level on the images as they are: mean IoU
(over the classes present, unknown ignored, as evaluate.py) and the share of roof-obstacle pixels
(classes 5-14) called landable (rooftop, as safety.py), appended as a JSON line to `--val-log`
(default: suffix .val.jsonl). The `--keep-best` checkpoints with the highest
score = mean IoU - roof obstacles called landable are kept as candidates
(`<out stem>.best-step<STEP>.pt`, listed in `<out stem>.candidates.json`); which one ships is for
the service-level evaluation to decide.

Example (the shipped model's third stage):
  .venvs/train/bin/python models/training/train.py --arch mobilenet_fcn8s \
      --train /work/data/train --init-onnx models/rooftop-segmentation.onnx --batch 8 --lr 1.5e-3 \
      --balance 0.5 --threads 1 --minutes 115 --out /work/runs/mobilenet_fcn8s_v2.pt
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parent))
from evaluate import iou_from_confusion  # noqa: E402
from safety import ROOF_OBSTACLES, ROOFTOP  # noqa: E402
from seg.data import LazySplit, load_split, to_input, to_target  # noqa: E402
from seg.warm_start import load_onnx_weights, onnx_training  # noqa: E402
from seg.models import ARCHITECTURES, NUM_CLASSES, NUM_OUTPUTS, build, count_parameters  # noqa: E402

WARMUP = 0.03
# What a resumed run must share with the checkpoint it continues (the rest may change).
RESUME_FIELDS = ("arch", "width", "train", "size", "limit", "crop", "batch", "lr", "seed",
                 "balance", "total_steps")


def parse_size(text: str | None):
    if not text:
        return None
    w, h = text.lower().split("x")
    return int(w), int(h)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--arch", choices=ARCHITECTURES, default="mobilenet_fcn8s")
    p.add_argument("--width", type=float, default=0.5, help="backbone width multiplier")
    p.add_argument("--train", required=True, help="dataset directory (landing-sim dataset --split train)")
    p.add_argument("--size", help="train at WxH (resizes the data), default: the data's size")
    p.add_argument("--limit", type=int, help="use only the first N training images")
    p.add_argument("--crop", help="train on random WxH crops (cheaper steps; the network is fully "
                                  "convolutional and is evaluated on whole images)")
    p.add_argument("--minutes", type=float, default=30.0, help="this session's wall-clock budget")
    p.add_argument("--epochs", type=int, default=1000, help="schedule length in passes when "
                                                            "neither --total-steps nor --steps")
    p.add_argument("--steps", type=int, help="at most this many steps in this session (smoke "
                                             "tests); also the schedule length without --total-steps")
    p.add_argument("--total-steps", type=int, help="the schedule's length in steps (all sessions)")
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--lr", type=float, default=3e-3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--init", help="start from this checkpoint's weights (fine-tuning) instead of "
                                  "from scratch")
    p.add_argument("--init-onnx", help="start from the weights of an exported model (e.g. the "
                                       "shipped one) of the same architecture and width (an FCN4s "
                                       "may start from an FCN8s)")
    p.add_argument("--balance", type=float, default=0.3,
                   help="class weight exponent: (median / freq)^balance, 0 = unweighted")
    p.add_argument("--out", required=True, help="checkpoint path (.pt)")
    p.add_argument("--resume", action="store_true", help="continue from --out if it exists")
    p.add_argument("--checkpoint-minutes", type=float, default=5.0)
    p.add_argument("--log", help="log file, appended (default: --out with suffix .log)")
    p.add_argument("--log-every", type=int, default=20, help="log a line every N steps")
    p.add_argument("--val", help="validation dataset directory (development worlds)")
    p.add_argument("--val-minutes", type=float, default=30.0)
    p.add_argument("--val-log", help="validation JSON lines (default: --out with suffix .val.jsonl)")
    p.add_argument("--keep-best", type=int, default=3, help="candidate checkpoints kept by score")
    args = p.parse_args(argv)
    for name in ("total_steps", "steps", "batch", "log_every"):
        value = getattr(args, name)
        if value is not None and value < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1, got {value}")
    if args.minutes <= 0 or args.checkpoint_minutes <= 0:
        p.error("--minutes and --checkpoint-minutes must be positive")
    return args


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


def lr_at(step: int, total: int, base: float) -> float:
    """Warm-up from base/10 over the first 3 % of the steps, then cosine down to base/50."""
    progress = step / total
    if progress < WARMUP:
        return base * (0.1 + 0.9 * progress / WARMUP)
    q = (progress - WARMUP) / (1 - WARMUP)
    return base * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(q, 1.0))))


def epoch_order(seed: int, epoch: int, n: int) -> np.ndarray:
    """The data order of one epoch: a function of the seed and the epoch only (resumable)."""
    return np.random.default_rng([seed, epoch]).permutation(n)


def save_atomic(obj, path: Path) -> None:
    """torch.save to a temporary file in the same directory, fsync, rename over `path`."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        torch.save(obj, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


class Log:
    def __init__(self, path: Path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self.file = open(path, "a", buffering=1)

    def __call__(self, text: str) -> None:
        line = f"{time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())} {text}"
        print(line, flush=True)
        self.file.write(line + "\n")


def make_batch(data: LazySplit, idx: np.ndarray, rng: np.random.Generator, crop):
    """One training batch: crop (if any), horizontal flips, per-image brightness/contrast."""
    images, labels = data.batch(idx)
    if crop is not None:
        cw, ch = crop
        x0 = int(rng.integers(0, data.width - cw + 1))
        y0 = int(rng.integers(0, data.height - ch + 1))
        images, labels = images[:, y0:y0 + ch, x0:x0 + cw], labels[:, y0:y0 + ch, x0:x0 + cw]
    x, y = to_input(images), to_target(labels)
    flip = torch.from_numpy(rng.random(len(idx)) < 0.5)
    x[flip] = x[flip].flip(-1)
    y[flip] = y[flip].flip(-1)
    gain = torch.from_numpy(rng.uniform(0.8, 1.2, (len(idx), 1, 1, 1))).float()
    bias = torch.from_numpy(rng.uniform(-0.2, 0.2, (len(idx), 1, 1, 1))).float()
    return x * gain + bias, y


def validate(net, images: np.ndarray, labels: np.ndarray) -> dict:
    """Pixel-level validation at the images' own size: mean IoU (evaluate.py's definition),
    roof-obstacle pixels called landable and rooftop recall (safety.py's classes)."""
    conf = np.zeros((NUM_CLASSES, NUM_CLASSES), dtype=np.int64)
    net.eval()
    with torch.no_grad():
        for i in range(0, len(images), 8):
            pred = (net(to_input(images[i:i + 8])).argmax(1) + 1).numpy()
            truth = labels[i:i + 8]
            keep = truth != 0
            conf += np.bincount(truth[keep].astype(np.int64) * NUM_CLASSES + pred[keep],
                                minlength=NUM_CLASSES * NUM_CLASSES).reshape(NUM_CLASSES, NUM_CLASSES)
    net.train()
    iou = iou_from_confusion(conf)
    obstacles = list(ROOF_OBSTACLES)
    obstacle_pixels = int(conf[obstacles, 1:].sum())
    return {
        "mean_iou": iou["mean_iou"],
        "obstacles_landable": float(conf[obstacles, ROOFTOP].sum() / max(obstacle_pixels, 1)),
        "rooftop_recall": float(conf[ROOFTOP, ROOFTOP] / max(conf[ROOFTOP, 1:].sum(), 1)),
        "per_class": iou["per_class"],
    }


def score(val: dict) -> float:
    """The candidates' ranking: mean IoU minus the share of roof-obstacle pixels called landable."""
    return val["mean_iou"] - val["obstacles_landable"]


def keep_candidate(out: Path, ckpt: dict, val: dict, step: int, keep: int, log: Log) -> None:
    """Saves this checkpoint's weights as a candidate if it is among the `keep` best by score,
    and removes the one it displaces."""
    index_path = out.with_name(out.stem + ".candidates.json")
    cands = json.loads(index_path.read_text()) if index_path.exists() else []
    cands = [c for c in cands if c["step"] != step]
    entry = {"step": step, "score": score(val), "mean_iou": val["mean_iou"],
             "obstacles_landable": val["obstacles_landable"],
             "path": str(out.with_name(f"{out.stem}.best-step{step:07d}.pt"))}
    ranked = sorted(cands + [entry], key=lambda c: -c["score"])
    kept, dropped = ranked[:keep], ranked[keep:]
    if entry in kept:
        save_atomic({k: v for k, v in ckpt.items() if k != "resume"}, Path(entry["path"]))
        log(f"candidate kept: step {step} score {entry['score']:.4f}")
    for c in dropped:
        Path(c["path"]).unlink(missing_ok=True)
    tmp = index_path.with_name(index_path.name + ".tmp")
    tmp.write_text(json.dumps(kept, indent=1) + "\n")
    os.replace(tmp, index_path)


def config_of(args, data: LazySplit, total_steps: int) -> dict:
    return {"arch": args.arch, "width": args.width, "train": str(Path(args.train).resolve()),
            "size": args.size, "limit": args.limit, "crop": args.crop, "batch": args.batch,
            "lr": args.lr, "seed": args.seed, "balance": args.balance, "total_steps": total_steps,
            "images": len(data)}


def check_resumable(saved: dict, config: dict, out: Path) -> None:
    for field in RESUME_FIELDS:
        if saved.get(field) != config[field]:
            raise SystemExit(f"--resume: {out} was started with {field}={saved.get(field)!r}, "
                             f"this command has {field}={config[field]!r}; use the same or a new --out")


def initial_state(args, net, data: LazySplit, log: Log) -> dict:
    """A fresh run: initial weights (from scratch, --init or --init-onnx) and class weights."""
    sample = np.linspace(0, len(data) - 1, num=min(len(data), 2000)).round().astype(int)
    _, labels = data.batch(np.unique(sample))
    weights = class_weights(labels, args.balance)
    prior = None
    if args.init:
        prior = torch.load(args.init, map_location="cpu", weights_only=False)
        if prior["arch"] != args.arch or prior["width"] != args.width:
            raise SystemExit(f"--init {args.init} is {prior['arch']} x{prior['width']}")
        net.load_state_dict(prior["state_dict"])
    if args.init_onnx:
        pick = np.random.default_rng(args.seed).choice(len(data), size=min(len(data), 32), replace=False)
        load_onnx_weights(net, args.init_onnx, to_input(data.batch(pick)[0]))
        log(f"initialised from {args.init_onnx}")
    return {"step": 0, "epoch": 0, "pos": 0, "seen": 0, "loss_avg": None, "train_seconds": 0.0,
            "sessions": 0, "weights": weights.tolist(), "np_rng": None, "torch_rng": None,
            "optimizer": None, "last_val_s": None,
            "previous": prior["training"] if prior else onnx_training(args.init_onnx),
            "init": args.init or args.init_onnx}


def checkpoint(args, net, opt, rng, state: dict, config: dict, data: LazySplit) -> dict:
    state.update(optimizer=opt.state_dict(), np_rng=rng.bit_generator.state,
                 torch_rng=torch.get_rng_state())
    training = {
        "dataset": config["train"], "images": len(data), "epochs": round(state["seen"] / len(data), 2),
        "steps": state["step"], "total_steps": config["total_steps"], "batch": args.batch,
        "crop": args.crop, "minutes": round(state["train_seconds"] / 60.0, 1),
        "sessions": state["sessions"], "threads": args.threads, "lr": args.lr,
        "final_loss": state["loss_avg"], "seed": args.seed,
        "command": " ".join([os.path.relpath(sys.argv[0])] + sys.argv[1:]),
        "torch": torch.__version__, "init": state["init"], "balance": args.balance,
        "previous": state["previous"],
    }
    return {"arch": args.arch, "width": args.width, "state_dict": net.state_dict(),
            "input_size": [data.width, data.height], "training": training,
            "resume": {"config": config, **state}}


def load_or_start(args, net, data: LazySplit, config: dict, out: Path, log: Log):
    if args.resume and out.exists():
        ckpt = torch.load(out, map_location="cpu", weights_only=False)
        if "resume" not in ckpt:
            raise SystemExit(f"--resume: {out} has no resume state (written by an older train.py)")
        state = ckpt["resume"]
        check_resumable(state.pop("config"), config, out)
        net.load_state_dict(ckpt["state_dict"])
        log(f"resumed from {out} at step {state['step']} (epoch {state['epoch']}, "
            f"batch {state['pos']} of the epoch, {state['train_seconds'] / 60:.1f} min trained)")
        return state
    return initial_state(args, net, data, log)


def run_validation(args, net, val_data, ckpt: dict, state: dict, out: Path, val_log: Path, log: Log):
    t = time.time()
    val = validate(net, *val_data)
    state["last_val_s"] = state["train_seconds"]
    record = {"step": state["step"], "epoch": round(state["seen"] / ckpt["training"]["images"], 3),
              "time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "score": score(val),
              "val": args.val, "val_images": int(len(val_data[0])), **val}
    with open(val_log, "a") as f:
        f.write(json.dumps(record) + "\n")
    log(f"validation step {state['step']}: mean IoU {val['mean_iou']:.4f}, roof obstacles "
        f"called landable {100 * val['obstacles_landable']:.2f} %, rooftop recall "
        f"{100 * val['rooftop_recall']:.2f} % ({time.time() - t:.0f}s)")
    keep_candidate(out, ckpt, val, state["step"], args.keep_best, log)


def train_step(net, opt, x, y, weights, lr: float) -> float:
    for g in opt.param_groups:
        g["lr"] = lr
    net.train()
    loss = F.cross_entropy(net(x), y, weight=weights, ignore_index=255)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    return loss.item()


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    log = Log(Path(args.log) if args.log else out.with_suffix(".log"))
    val_log = Path(args.val_log) if args.val_log else out.with_suffix(".val.jsonl")
    torch.set_num_threads(args.threads)
    stop = {"signal": None}

    def on_signal(signum, _frame):
        stop["signal"] = signal.Signals(signum).name

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)

    data = LazySplit(args.train, limit=args.limit, size=parse_size(args.size))
    n, crop = len(data), parse_size(args.crop)
    if crop is not None and (crop[0] > data.width or crop[1] > data.height):
        raise SystemExit(f"--crop {args.crop} is larger than the {data.width}x{data.height} images")
    steps_per_epoch = max(1, n // args.batch)
    total_steps = args.total_steps or args.steps or args.epochs * steps_per_epoch
    config = config_of(args, data, total_steps)
    log(f"start: {n} images {data.width}x{data.height} from {args.train}, {args.arch} "
        f"x{args.width}, schedule {total_steps} steps of {args.batch}, session budget "
        f"{args.minutes} min, pid {os.getpid()}")
    torch.manual_seed(args.seed)
    net = build(args.arch, args.width)
    state = load_or_start(args, net, data, config, out, log)
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=1e-4)
    rng = np.random.default_rng(args.seed)
    if state["optimizer"] is not None:
        opt.load_state_dict(state["optimizer"])
        rng.bit_generator.state = state["np_rng"]
        torch.set_rng_state(state["torch_rng"])
    weights = torch.tensor(state["weights"], dtype=torch.float32)
    log(f"{count_parameters(net)} parameters; class weights {[round(w, 2) for w in state['weights']]}")
    val_data = load_split(args.val) if args.val else None
    state["sessions"] += 1
    return session(args, net, opt, rng, weights, state, config, data, val_data, out, val_log,
                   log, stop)


def session(args, net, opt, rng, weights, state, config, data, val_data, out, val_log, log, stop):
    """Trains until the schedule ends, the session's budget or --steps is spent, or a signal."""
    n, total, crop = len(data), config["total_steps"], parse_size(args.crop)
    steps_per_epoch = max(1, n // args.batch)
    start = last_ckpt = time.time()
    base_seconds, session_steps, session_seen = state["train_seconds"], 0, 0
    order = epoch_order(args.seed, state["epoch"], n)
    reason = "schedule done"
    # The starting point, for comparison (once: not again after a resume at step 0).
    if state["step"] == 0 and state["last_val_s"] is None and val_data is not None:
        save(args, net, opt, rng, state, config, data, val_data, out, val_log, log, force_val=True)
    while state["step"] < total:
        if stop["signal"] or time.time() - start >= args.minutes * 60 or session_steps == args.steps:
            reason = stop["signal"] or ("--steps" if session_steps == args.steps else "--minutes")
            break
        if state["pos"] >= steps_per_epoch:
            state["epoch"], state["pos"] = state["epoch"] + 1, 0
            order = epoch_order(args.seed, state["epoch"], n)
        idx = order[state["pos"] * args.batch:(state["pos"] + 1) * args.batch]
        x, y = make_batch(data, idx, rng, crop)
        lr = lr_at(state["step"], total, args.lr)
        loss = train_step(net, opt, x, y, weights, lr)
        state["step"] += 1
        state["pos"] += 1
        state["seen"] += len(idx)
        session_steps, session_seen = session_steps + 1, session_seen + len(idx)
        state["loss_avg"] = loss if state["loss_avg"] is None else 0.95 * state["loss_avg"] + 0.05 * loss
        state["train_seconds"] = base_seconds + time.time() - start
        if state["step"] % args.log_every == 0 or session_steps == 1:
            log(f"step {state['step']}/{total} epoch {state['epoch']} loss {state['loss_avg']:.4f} "
                f"lr {lr:.2e} {session_seen / max(time.time() - start, 1e-6):.1f} img/s")
        if time.time() - last_ckpt >= args.checkpoint_minutes * 60:
            save(args, net, opt, rng, state, config, data, val_data, out, val_log, log, force_val=False)
            last_ckpt = time.time()
    # A signal asks for a quick exit: checkpoint only, no validation.
    save(args, net, opt, rng, state, config, data, val_data if not stop["signal"] else None,
         out, val_log, log, force_val=True)
    print(json.dumps({"saved": str(out), **checkpoint(args, net, opt, rng, state, config, data)["training"]},
                     default=str), flush=True)
    log(f"session end ({reason}) at step {state['step']}/{total}, loss {state['loss_avg']}, "
        f"{session_steps} steps in {(time.time() - start) / 60:.1f} min")
    return 0


def save(args, net, opt, rng, state, config, data, val_data, out, val_log, log, force_val: bool) -> None:
    """Writes the resumable checkpoint; validates first when due or forced."""
    ckpt = checkpoint(args, net, opt, rng, state, config, data)
    due = state["last_val_s"] is None or \
        state["train_seconds"] - state["last_val_s"] >= args.val_minutes * 60
    if val_data is not None and (force_val or due):
        run_validation(args, net, val_data, ckpt, state, out, val_log, log)
        ckpt = checkpoint(args, net, opt, rng, state, config, data)
    save_atomic(ckpt, out)
    log(f"checkpoint step {state['step']} -> {out}")


if __name__ == "__main__":
    sys.exit(main())
