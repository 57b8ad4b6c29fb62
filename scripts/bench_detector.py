#!/usr/bin/env python3
"""Throughput of the built-in YOLOX-nano detector against onnxruntime, in the same run.

Both run the same model on the same real 1080p frames (BrnoCompSpeed screen.png, read from
VPCAL_DATA), the same regions (the whole frame plus the tiles of `--tiles`), the same
resampling (exact area averaging, scripts/yolox_goldens.py) and decoding. onnxruntime gets
as many intra-op threads as vpcal has cores (2 here). Prints frames/s of each and the ratio.

Usage: python3 scripts/bench_detector.py [--vpcal target/release/vpcal] [--tiles 0 2 3] [--repeat 3]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import onnxruntime as ort
import cv2

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import yolox_goldens as yg  # noqa: E402


def tile_regions(width, height, columns, overlap=0.2):
    """The same tiles as vpcal-video's yolox::tile_regions."""
    if columns == 0:
        return []
    side = int(np.ceil(width / columns * (1 + overlap)))
    side = max(1, min(side, width, height))
    step = max(1.0, side * (1 - overlap))

    def count(total):
        return 1 if total <= side else 1 + int(np.ceil((total - side) / step))

    def spread(total, n):
        if n <= 1 or side >= total:
            return [0]
        return [int(round((total - side) * i / (n - 1))) for i in range(n)]

    return [(x, y, side, side) for y in spread(height, count(height)) for x in spread(width, count(width))]


def letterbox_cv2(rgb, region):
    """The peer's preprocessing: OpenCV's area resampling (the same average as vpcal's for
    downscaling), BGR, 114 padding."""
    x0, y0, w, h = region
    ow, oh = yg.fit_size(w, h)
    crop = rgb[y0:y0 + h, x0:x0 + w, ::-1]
    small = cv2.resize(crop, (ow, oh), interpolation=cv2.INTER_AREA)
    out = np.full((yg.INPUT, yg.INPUT, 3), yg.PAD, dtype=np.float32)
    out[:oh, :ow] = small
    return np.ascontiguousarray(out.transpose(2, 0, 1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--vpcal", default="target/release/vpcal")
    ap.add_argument("--tiles", type=int, nargs="+", default=[0, 2])
    ap.add_argument("--repeat", type=int, default=2, help="passes over the frames")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    args = ap.parse_args()
    data = os.environ.get("VPCAL_DATA", os.path.join(yg.HERE, "..", "..", "shared", "data"))
    bcs = os.path.join(data, "bcs", "dataset")
    frames = sorted(os.path.join(bcs, d, "screen.png") for d in os.listdir(bcs)
                    if os.path.isfile(os.path.join(bcs, d, "screen.png")))
    tmp = tempfile.mkdtemp(prefix="vpcal-bench-det-")
    images = []
    k = 0
    for _ in range(args.repeat):
        for f in frames:
            dst = os.path.join(tmp, f"{k:04d}.png")
            os.symlink(os.path.abspath(f), dst)
            k += 1
    for f in frames:
        images.append(cv2.cvtColor(cv2.imread(f), cv2.COLOR_BGR2RGB))
    so = ort.SessionOptions()
    so.intra_op_num_threads = args.threads
    so.inter_op_num_threads = 1
    sess = ort.InferenceSession(yg.MODEL, so, providers=["CPUExecutionProvider"])
    print(f"{len(frames) * args.repeat} real 1920x1080 frames, {args.threads} threads, onnxruntime {ort.__version__}")
    print(f"{'tiles':>5} {'regions':>7} {'onnxruntime f/s':>16} {'vpcal f/s':>10} {'ratio':>6}")
    for t in args.tiles:
        regions = [None] + tile_regions(1920, 1080, t)
        t0 = time.perf_counter()
        for _ in range(args.repeat):
            for rgb in images:
                H, W, _ = rgb.shape
                for reg in regions:
                    r = reg if reg is not None else (0, 0, W, H)
                    tensor = letterbox_cv2(rgb, r)
                    raw = sess.run(None, {"images": tensor[None]})[0][0]
                    boxes, score, _cls = yg.decode(raw)
                    keep = score > yg.MIN_SCORE
                    yg.nms(boxes[keep], score[keep])
        ort_fps = len(images) * args.repeat / (time.perf_counter() - t0)
        out = subprocess.run(
            [args.vpcal, "detect", tmp, "-o", os.path.join(tmp, "dets.csv"), "--detector", "yolox",
             "--tiles", str(t), "--json", "--quiet"],
            check=True, capture_output=True, text=True)
        ours = json.loads(out.stdout)["detector_frames_per_s"]
        print(f"{t:>5} {len(regions):>7} {ort_fps:>16.2f} {ours:>10.2f} {ours / ort_fps:>6.2f}")


if __name__ == "__main__":
    main()
