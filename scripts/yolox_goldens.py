#!/usr/bin/env python3
"""Golden outputs of the bundled YOLOX-nano detector, computed with onnxruntime.

The Rust detector (`vpcal-video/src/detect/yolox.rs`) must give the same boxes on the same
real frames: its test reads the frames from ../shared (VPCAL_DATA) and compares its detections
with the ones this script writes (box corners within 0.5 px, scores within 1e-4).

This script is an independent implementation of the same convention (see
models/yolox_nano_coco/NOTICE and the module docs of yolox.rs):

- a region of the frame (the whole frame, or a tile) is resampled by exact area averaging
  (each output pixel is the mean of the source area it covers, fractional pixels weighted by
  their overlap) to the largest size that fits the 416 x 416 input, keeping the aspect ratio,
  into the top-left corner; the rest is 114; channels BGR, values 0-255 as float32;
- decoding: anchor points of strides 8, 16, 32 in row-major order (x fastest), centre
  (grid + (dx, dy)) * stride, size exp(log w, log h) * stride;
- vehicle score = objectness x best class score among car 2, motorcycle 3, bus 5, truck 7;
  candidates above MIN_SCORE, class-agnostic greedy NMS at IoU NMS_IOU;
- boxes mapped back to frame pixels per axis and clamped to the region.

Usage: python3 scripts/yolox_goldens.py [DATA_DIR] > crates/vpcal-video/tests/golden/yolox.json
Needs onnxruntime, numpy and opencv-python-headless (PyPI; OpenCV only reads the PNGs).
"""
import hashlib
import json
import os
import sys

import numpy as np
import onnxruntime as ort
import cv2

INPUT = 416
STRIDES = (8, 16, 32)
VEHICLES = (2, 3, 5, 7)
MIN_SCORE = 0.25
NMS_IOU = 0.45
PAD = 114.0

HERE = os.path.dirname(os.path.abspath(__file__))
MODEL = os.path.join(HERE, "..", "models", "yolox_nano_coco", "yolox_nano.onnx")

# (path under DATA_DIR, regions as (x0, y0, w, h) or None for the whole frame)
FRAMES = [
    ("bcs/dataset/session0_center/screen.png", [None, (0, 0, 960, 540), (700, 100, 800, 450)]),
    ("bcs/dataset/session2_left/screen.png", [None, (960, 0, 960, 540)]),
    ("real/kitti_object/image_2/000001.png", [None]),
    ("real/kitti_object/image_2/000007.png", [None]),
]


def area_weights(src_len, offset, length, out_len):
    """Matrix (out_len x src_len): row i averages [offset + i*s, offset + (i+1)*s)."""
    s = length / out_len
    w = np.zeros((out_len, src_len), dtype=np.float64)
    for i in range(out_len):
        a = offset + i * s
        b = offset + (i + 1) * s
        j0 = int(np.floor(a))
        j1 = min(int(np.ceil(b)), offset + length)  # b may overshoot by a rounding error
        for j in range(j0, j1):
            ov = min(b, j + 1) - max(a, j)
            if ov > 0 and 0 <= j < src_len:
                w[i, j] = ov / s
    return w


def fit_size(w, h):
    r = min(INPUT / w, INPUT / h)
    ow = min(INPUT, max(1, int(np.floor(w * r + 0.5))))
    oh = min(INPUT, max(1, int(np.floor(h * r + 0.5))))
    return ow, oh


def letterbox(rgb, region):
    H, W, _ = rgb.shape
    x0, y0, w, h = region
    ow, oh = fit_size(w, h)
    wx = area_weights(W, x0, w, ow)
    wy = area_weights(H, y0, h, oh)
    img = rgb.astype(np.float64)
    out = np.full((3, INPUT, INPUT), PAD, dtype=np.float32)
    for c_out, c_in in enumerate((2, 1, 0)):  # BGR
        out[c_out, :oh, :ow] = (wy @ img[:, :, c_in] @ wx.T).astype(np.float32)
    return out, (ow, oh)


def decode(raw):
    rows = []
    k = 0
    for s in STRIDES:
        n = INPUT // s
        for gy in range(n):
            for gx in range(n):
                rows.append((gx, gy, s))
                k += 1
    assert k == raw.shape[0], (k, raw.shape)
    g = np.array(rows, dtype=np.float64)
    r = raw.astype(np.float64)
    cx = (g[:, 0] + r[:, 0]) * g[:, 2]
    cy = (g[:, 1] + r[:, 1]) * g[:, 2]
    bw = np.exp(r[:, 2]) * g[:, 2]
    bh = np.exp(r[:, 3]) * g[:, 2]
    cls = r[:, [5 + c for c in VEHICLES]]
    best = cls.argmax(axis=1)
    score = r[:, 4] * cls.max(axis=1)
    boxes = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=1)
    return boxes, score, np.array(VEHICLES)[best]


def iou(a, b):
    iw = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    ih = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = iw * ih
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def nms(boxes, scores):
    order = np.argsort(-scores, kind="stable")
    kept = []
    for i in order:
        if all(iou(boxes[i], boxes[k]) <= NMS_IOU for k in kept):
            kept.append(i)
    return kept


def main():
    data = sys.argv[1] if len(sys.argv) > 1 else os.environ.get(
        "VPCAL_DATA", os.path.join(HERE, "..", "..", "shared", "data"))
    with open(MODEL, "rb") as f:
        sha1 = hashlib.sha1(f.read()).hexdigest()
    sess = ort.InferenceSession(MODEL, providers=["CPUExecutionProvider"])
    cases = []
    for rel, regions in FRAMES:
        rgb = cv2.cvtColor(cv2.imread(os.path.join(data, rel), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        H, W, _ = rgb.shape
        for region in regions:
            reg = region if region is not None else (0, 0, W, H)
            x0, y0, w, h = reg
            tensor, (ow, oh) = letterbox(rgb, reg)
            raw = sess.run(None, {"images": tensor[None]})[0][0]
            boxes, score, cls = decode(raw)
            keep = score > MIN_SCORE
            boxes, score, cls = boxes[keep], score[keep], cls[keep]
            sx, sy = w / ow, h / oh
            dets = []
            for i in nms(boxes, score):
                b = boxes[i]
                fb = [
                    float(np.clip(x0 + b[0] * sx, x0, x0 + w)),
                    float(np.clip(y0 + b[1] * sy, y0, y0 + h)),
                    float(np.clip(x0 + b[2] * sx, x0, x0 + w)),
                    float(np.clip(y0 + b[3] * sy, y0, y0 + h)),
                ]
                dets.append({"box": fb, "score": float(score[i]), "class": int(cls[i])})
            cases.append({
                "frame": rel,
                "size": [W, H],
                "region": list(reg),
                "resized": [ow, oh],
                "detections": dets,
            })
    json.dump({
        "model_sha1": sha1,
        "input": INPUT,
        "min_score": MIN_SCORE,
        "nms_iou": NMS_IOU,
        "classes": list(VEHICLES),
        "onnxruntime": ort.__version__,
        "cases": cases,
    }, sys.stdout, indent=1)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
