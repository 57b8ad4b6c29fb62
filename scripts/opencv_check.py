#!/usr/bin/env python3
"""The OpenCV block of a calibration file against `vpcal measure`.

Projects a grid of road points (road frame of docs/calibration-file.md, z = 0) with
`cv2.projectPoints` and the file's `opencv` block, then asks `vpcal measure` for the distances
between their pixels; each must equal the distance between the road points to 1e-6 relative.
Runs on the file as it is (road units) and, after `vpcal scale` into a copy, in metres.

Usage: python3 scripts/opencv_check.py CALIB.json [--vpcal target/release/vpcal]
(e.g. the demo's vpcal-demo/calib.json). Needs opencv-python-headless and numpy from PyPI.
"""
import argparse
import itertools
import json
import shutil
import subprocess
import sys
import tempfile

import cv2
import numpy as np


def check(vpcal, calib_path):
    doc = json.load(open(calib_path))
    cv = doc["opencv"]
    # Road points ahead of the camera, along and across the road, in the file's units.
    height = np.linalg.norm(cv["tvec"])
    along = [1.0, 2.0, 4.0]
    across = [-1.0, 0.0, 1.5]
    road = np.array([[a * height, c * height, 0.0] for a in along for c in across])
    pixels, _ = cv2.projectPoints(
        road,
        np.array(cv["rvec"], dtype=np.float64),
        np.array(cv["tvec"], dtype=np.float64),
        np.array(cv["camera_matrix"], dtype=np.float64),
        np.array(cv["dist_coeffs"], dtype=np.float64),
    )
    pixels = pixels.reshape(-1, 2)
    pairs = list(itertools.combinations(range(len(road)), 2))
    args = [vpcal, "measure", calib_path, "--json"]
    for i, j in pairs:
        args += ["--points", "%.17g,%.17g,%.17g,%.17g" % (*pixels[i], *pixels[j])]
    rows = json.loads(subprocess.run(args, check=True, capture_output=True, text=True).stdout)
    worst = 0.0
    for (i, j), row in zip(pairs, rows):
        truth = float(np.linalg.norm(road[i] - road[j]))
        if row["distance"] is None:
            sys.exit(f"pixel pair {i}-{j} does not see the road")
        worst = max(worst, abs(row["distance"] - truth) / truth)
    print(f"{calib_path}: {len(pairs)} distances in {cv['units']}, "
          f"worst relative difference {worst:.2e}")
    return worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("calib")
    ap.add_argument("--vpcal", default="target/release/vpcal")
    a = ap.parse_args()
    worst = check(a.vpcal, a.calib)
    with tempfile.TemporaryDirectory() as tmp:
        scaled = f"{tmp}/scaled.json"
        shutil.copy(a.calib, scaled)
        doc = json.load(open(scaled))
        w, h = doc["image_size"]
        # Any road distance makes a scale; these two pixels are on the road below the horizon.
        subprocess.run([a.vpcal, "scale", scaled, "--points",
                        f"{w * 0.4},{h * 0.9},{w * 0.6},{h * 0.9}", "--distance", "3.5"],
                       check=True, capture_output=True)
        worst = max(worst, check(a.vpcal, scaled))
    if worst > 1e-6:
        sys.exit(f"FAIL: {worst:.2e} > 1e-6")
    print("OK: cv2.projectPoints and vpcal measure agree")


if __name__ == "__main__":
    main()
