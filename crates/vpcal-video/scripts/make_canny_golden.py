#!/usr/bin/env python3
"""Golden edge maps from OpenCV's Canny for vpcal-video's `canny_opencv` test, and golden
crop resizes (cv2.resize INTER_LINEAR / INTER_CUBIC) for the crop filters.

Writes tests/fixtures/canny_input.png (a synthetic 8-bit grey image: gradients, shapes, text-like
strokes and noise; deterministic) and tests/fixtures/canny_opencv_100_200.png
(cv2.Canny(input, 100, 200), the reference's call), plus canny_opencv_30_90.png.

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy opencv-python-headless
    /tmp/venv/bin/python scripts/make_canny_golden.py

With --compare IMAGE it instead prints how many pixels of Canny(IMAGE) differ between OpenCV
and the PNG given as --ours (for checking on real frames without committing them).
"""
import argparse
import os

import cv2
import numpy as np


def synthetic():
    rng = np.random.RandomState(7)
    h, w = 72, 96
    y, x = np.mgrid[0:h, 0:w]
    img = (60 + 1.2 * x + 0.5 * y).astype(np.float64)
    cv2.rectangle(img, (10, 8), (40, 30), 220, -1)
    cv2.circle(img, (65, 40), 16, 20, -1)
    cv2.line(img, (5, 60), (90, 50), 250, 2)
    cv2.ellipse(img, (30, 52), (14, 7), 25, 0, 360, 140, -1)
    pts = np.array([[70, 5], [92, 12], [85, 28]], np.int32)
    cv2.fillPoly(img, [pts], 180)
    img += rng.normal(0, 6, img.shape)
    # A soft edge and a weak edge, to exercise the hysteresis.
    img[:, 48:52] += np.linspace(0, 40, 4)
    img[60:, :20] += 25
    return np.clip(img, 0, 255).astype(np.uint8)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--compare")
    ap.add_argument("--ours")
    args = ap.parse_args()
    if args.compare:
        grey = cv2.imread(args.compare, cv2.IMREAD_COLOR)
        grey = cv2.cvtColor(grey, cv2.COLOR_BGR2GRAY)
        ref = cv2.Canny(grey, 100, 200)
        ours = cv2.imread(args.ours, cv2.IMREAD_GRAYSCALE)
        diff = int(np.count_nonzero(ref != ours))
        print(f"{args.compare}: {diff} of {ref.size} pixels differ; OpenCV edges {np.count_nonzero(ref)}, ours {np.count_nonzero(ours)}")
        return
    out = os.path.join(os.path.dirname(__file__), "..", "tests", "fixtures")
    img = synthetic()
    cv2.imwrite(os.path.join(out, "canny_input.png"), img)
    cv2.imwrite(os.path.join(out, "canny_opencv_100_200.png"), cv2.Canny(img, 100, 200))
    cv2.imwrite(os.path.join(out, "canny_opencv_30_90.png"), cv2.Canny(img, 30, 90))
    # Crop-and-resize goldens: rows 5..40, columns 10..50 of the input as an RGB image
    # (R = input, G = 255 - input, B = input / 2) resized to 128 x 128.
    rgb = np.dstack([img, 255 - img, img // 2])
    crop = rgb[5:40, 10:50]
    for name, interp in [("linear", cv2.INTER_LINEAR), ("cubic", cv2.INTER_CUBIC)]:
        out_img = cv2.resize(crop, (128, 128), interpolation=interp)
        cv2.imwrite(os.path.join(out, f"crop_opencv_{name}.png"), out_img[:, :, ::-1])
    print("OpenCV", cv2.__version__, "edges:", np.count_nonzero(cv2.Canny(img, 100, 200)), np.count_nonzero(cv2.Canny(img, 30, 90)))


if __name__ == "__main__":
    main()
