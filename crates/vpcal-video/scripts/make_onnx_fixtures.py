#!/usr/bin/env python3
"""Tiny ONNX models for the tests of vpcal-video's ONNX detector (feature `onnx`).

Both models take `images` [1, 3, 32, 32] (RGB in [0, 1]) and compute their scores from the
image with real operators, so the test checks that the input reaches the model:
score_k = mean(images) * w_k with w = (1.0, 0.9, 0.2).

- tiny_yolo.onnx: YOLOv8 layout, `output0` [1, 4 + 2, 3] = boxes (cx, cy, w, h in input pixels,
  constant) and two class rows: class 0 = the score, class 1 = 0.
  Box 0: centre (10, 12), 8 x 6; box 1: centre (10.5, 12), 8 x 6 (IoU 0.88 with box 0, so NMS
  drops it); box 2: centre (24, 24), 6 x 6 (score 0.2 * mean, under the default threshold).
- tiny_boxes_scores.onnx: two outputs, `boxes` [1, 3, 4] normalised x0, y0, x1, y1 (the same
  boxes) and `scores` [1, 3].

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install onnx numpy
    /tmp/venv/bin/python scripts/make_onnx_fixtures.py
"""
import os

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OUT = os.path.join(os.path.dirname(__file__), "..", "tests", "fixtures")
CXCYWH = np.array([[10, 12, 8, 6], [10.5, 12, 8, 6], [24, 24, 6, 6]], np.float32)
WEIGHTS = np.array([1.0, 0.9, 0.2], np.float32)


def score_nodes():
    """Nodes computing scores [1, 1, 3] = mean(images) * WEIGHTS."""
    return [
        helper.make_node("ReduceMean", ["images"], ["mean"], keepdims=1),  # [1, 1, 1, 1]
        helper.make_node("Reshape", ["mean", "shape111"], ["mean111"]),
        helper.make_node("Mul", ["mean111", "weights"], ["scores113"]),  # [1, 1, 3]
    ], [
        numpy_helper.from_array(np.array([1, 1, 1], np.int64), "shape111"),
        numpy_helper.from_array(WEIGHTS.reshape(1, 1, 3), "weights"),
    ]


def save(graph, name):
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, os.path.join(OUT, name))
    print("wrote", name)


def yolo():
    nodes, inits = score_nodes()
    boxes = CXCYWH.T.reshape(1, 4, 3)
    inits += [
        numpy_helper.from_array(boxes, "boxes"),
        numpy_helper.from_array(np.zeros((1, 1, 3), np.float32), "zeros"),
    ]
    nodes.append(helper.make_node("Concat", ["boxes", "scores113", "zeros"], ["output0"], axis=1))
    graph = helper.make_graph(
        nodes,
        "tiny_yolo",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 32, 32])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 6, 3])],
        inits,
    )
    save(graph, "tiny_yolo.onnx")


def boxes_scores():
    nodes, inits = score_nodes()
    c = CXCYWH
    xyxy = np.stack([c[:, 0] - c[:, 2] / 2, c[:, 1] - c[:, 3] / 2, c[:, 0] + c[:, 2] / 2, c[:, 1] + c[:, 3] / 2], 1) / 32.0
    inits += [
        numpy_helper.from_array(xyxy.astype(np.float32).reshape(1, 3, 4), "boxes_const"),
        numpy_helper.from_array(np.array([1, 3], np.int64), "shape13"),
    ]
    nodes += [
        helper.make_node("Identity", ["boxes_const"], ["boxes"]),
        helper.make_node("Reshape", ["scores113", "shape13"], ["scores"]),
    ]
    graph = helper.make_graph(
        nodes,
        "tiny_boxes_scores",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 32, 32])],
        [
            helper.make_tensor_value_info("boxes", TensorProto.FLOAT, [1, 3, 4]),
            helper.make_tensor_value_info("scores", TensorProto.FLOAT, [1, 3]),
        ],
        inits,
    )
    save(graph, "tiny_boxes_scores.onnx")


if __name__ == "__main__":
    yolo()
    boxes_scores()
