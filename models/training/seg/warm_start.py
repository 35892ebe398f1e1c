"""Continuing training from an exported ONNX model (`train.py --init-onnx`).

The exporter folds every BatchNorm into the convolution before it, so an exported graph holds one
weight and one bias per convolution, in the order the network runs them. Reloading maps the ONNX
`Conv` nodes, in graph order, onto the network's `Conv2d` modules in forward order (from the
smaller head it grew out of, skipping those marked `warm_start_skip`, which a larger head adds and
zero-initialises), and turns each
folded bias back into a BatchNorm that reproduces it:

    BN(x) = (x - m) / sqrt(v + eps) * g + b,  with m = mu, v = sigma^2 - eps, g = sigma, b = mu + bias

equals `x + bias` exactly in eval mode for any mu, sigma; choosing mu and sigma as the per-channel
mean and standard deviation of the convolution's output on real images makes train mode (batch
statistics) start from nearly the same function too.
"""

from __future__ import annotations

import json

import numpy as np
import onnx
import torch
from onnx import numpy_helper
from torch import nn


def _onnx_convs(path: str) -> list[tuple[np.ndarray, np.ndarray | None]]:
    model = onnx.load(path)
    init = {t.name: numpy_helper.to_array(t) for t in model.graph.initializer}
    convs = []
    for node in model.graph.node:
        if node.op_type != "Conv":
            continue
        weight = init[node.input[1]]
        bias = init[node.input[2]] if len(node.input) > 2 and node.input[2] else None
        convs.append((weight, bias))
    return convs


def _forward_order(net: nn.Module, example: torch.Tensor) -> list[nn.Conv2d]:
    order: list[nn.Conv2d] = []
    hooks = [m.register_forward_hook(lambda m, i, o: order.append(m))
             for m in net.modules() if isinstance(m, nn.Conv2d)]
    with torch.no_grad():
        net.eval()(example)
    for h in hooks:
        h.remove()
    return order


def _bn_after(net: nn.Module) -> dict[nn.Conv2d, nn.BatchNorm2d]:
    """Each convolution that a BatchNorm follows in the same nn.Sequential."""
    pairs = {}
    for seq in net.modules():
        if not isinstance(seq, nn.Sequential):
            continue
        children = list(seq.children())
        for a, b in zip(children, children[1:]):
            if isinstance(a, nn.Conv2d) and isinstance(b, nn.BatchNorm2d):
                pairs[a] = b
    return pairs


def load_onnx_weights(net: nn.Module, path: str, calibration: torch.Tensor) -> None:
    """Loads the folded weights of `path` into `net` (same architecture and width), calibrating
    the recreated BatchNorms on `calibration` (normalised NCHW images)."""
    convs = _onnx_convs(path)
    # From a model of the same architecture every convolution loads; from the smaller head it
    # grew out of (an FCN8s into an FCN4s), the convolutions new to `net` (the /4 scores) keep
    # their own initialisation.
    every = _forward_order(net, calibration[:1])
    inherited = [c for c in every if not getattr(c, "warm_start_skip", False)]
    order = next((o for o in (every, inherited) if len(o) == len(convs)), None)
    if order is None:
        raise ValueError(f"{path} has {len(convs)} convolutions, the network {len(every)} "
                         f"({len(inherited)} without the ones a larger head adds)")
    bns = _bn_after(net)
    folded_bias: dict[nn.Conv2d, torch.Tensor] = {}
    with torch.no_grad():
        for conv, (weight, bias) in zip(order, convs):
            if tuple(conv.weight.shape) != weight.shape:
                raise ValueError(f"shape mismatch: network {tuple(conv.weight.shape)}, "
                                 f"{path} {weight.shape}")
            conv.weight.copy_(torch.from_numpy(np.array(weight)))
            b = torch.from_numpy(np.array(bias)) if bias is not None else torch.zeros(weight.shape[0])
            if conv in bns:
                folded_bias[conv] = b
                bn = bns[conv]
                bn.running_mean.zero_()
                bn.running_var.fill_(1.0 - bn.eps)
                bn.weight.fill_(1.0)
                bn.bias.copy_(b)
            elif conv.bias is not None:
                conv.bias.copy_(b)
            else:
                raise ValueError("a folded bias with nowhere to go")

        # Calibrate: the eval-mode function does not depend on mu and sigma, so one pass with
        # hooks on the (exact) network gives every convolution's output statistics.
        stats: dict[nn.Conv2d, tuple[torch.Tensor, torch.Tensor]] = {}

        def record(m, _inputs, out):
            flat = out.transpose(0, 1).reshape(out.shape[1], -1)
            stats[m] = (flat.mean(1), flat.std(1).clamp_min(1e-2))

        hooks = [c.register_forward_hook(record) for c in bns if c in folded_bias]
        net.eval()(calibration)
        for h in hooks:
            h.remove()
        for conv, (mu, sigma) in stats.items():
            bn = bns[conv]
            bn.running_mean.copy_(mu)
            bn.running_var.copy_(sigma * sigma - bn.eps)
            bn.weight.copy_(sigma)
            bn.bias.copy_(mu + folded_bias[conv])


def onnx_training(path: str | None) -> dict | None:
    """The `training` metadata of an exported model (what trained it), if any."""
    if not path:
        return None
    meta = {p.key: p.value for p in onnx.load(path).metadata_props}
    return json.loads(meta["training"]) if "training" in meta else None
