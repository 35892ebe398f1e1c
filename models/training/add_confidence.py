#!/usr/bin/env python3
"""Adds the `confidence` output to an exported model that has only `classes`: round(255 x the
top class's softmax probability) as uint8 [1, H, W], computed from the logits the graph's ArgMax
takes, exactly what `export.py` now exports. The weights and the `classes` output are
unchanged. This is how the shipped model got its confidence without retraining.

Example:
  .venvs/train/bin/python models/training/add_confidence.py models/rooftop-segmentation.onnx \
      --out models/rooftop-segmentation.onnx
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper


def add_confidence(model: onnx.ModelProto) -> onnx.ModelProto:
    graph = model.graph
    if any(o.name == "confidence" for o in graph.output):
        raise SystemExit("the model already has a `confidence` output")
    argmax = [n for n in graph.node if n.op_type == "ArgMax"]
    if len(argmax) != 1:
        raise SystemExit(f"expected one ArgMax node, found {len(argmax)}")
    logits = argmax[0].input[0]
    const = lambda name, value: numpy_helper.from_array(np.array(value), name)  # noqa: E731
    graph.initializer.extend([const("confidence/axes", np.array([1], dtype=np.int64)),
                              const("confidence/scale", np.array(255.0, dtype=np.float32))])
    # The top probability is 1 / sum(exp(logit - max logit)). Softmax itself, over axis 1 of
    # NCHW, made ONNX Runtime transpose the whole tensor and doubled the model's time.
    graph.node.extend([
        helper.make_node("ReduceMax", [logits, "confidence/axes"], ["confidence/max"], keepdims=1),
        helper.make_node("Sub", [logits, "confidence/max"], ["confidence/shifted"]),
        helper.make_node("Exp", ["confidence/shifted"], ["confidence/exp"]),
        helper.make_node("ReduceSum", ["confidence/exp", "confidence/axes"], ["confidence/sum"],
                         keepdims=0),
        helper.make_node("Div", ["confidence/scale", "confidence/sum"], ["confidence/scaled"]),
        helper.make_node("Round", ["confidence/scaled"], ["confidence/rounded"]),
        helper.make_node("Cast", ["confidence/rounded"], ["confidence"], to=TensorProto.UINT8),
    ])
    graph.output.append(helper.make_tensor_value_info("confidence", TensorProto.UINT8,
                                                      [1, "height", "width"]))
    onnx.checker.check_model(model)
    return model


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    model = add_confidence(onnx.load(args.model))
    onnx.save(model, args.out)
    print(f"wrote {args.out}: outputs {[o.name for o in model.graph.output]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
