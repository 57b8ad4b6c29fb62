#!/usr/bin/env python3
"""The OpenCV export of a calibration against `vpcal measure`.

Projects a grid of road points (road frame of docs/calibration-file.md, z = 0) with
`cv2.projectPoints` and the camera as OpenCV reads it from `vpcal export --opencv` (a
FileStorage YAML file, read with cv2.FileStorage; it must match the calibration file's
`opencv` block), then asks `vpcal measure` for the distances between their pixels; each must
equal the distance between the road points to 1e-6 relative. Runs on the file as it is (road
units) and, after `vpcal scale` into a copy, in metres.

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


def from_yaml(vpcal, calib_path, tmp):
    """The camera as cv2.FileStorage reads `vpcal export --opencv`."""
    yml = f"{tmp}/camera.yml"
    subprocess.run([vpcal, "export", calib_path, "--opencv", yml], check=True, capture_output=True)
    fs = cv2.FileStorage(yml, cv2.FILE_STORAGE_READ)
    cam = {k: fs.getNode(k).mat() for k in ("camera_matrix", "distortion_coefficients", "rvec", "tvec")}
    units = fs.getNode("units").string()
    fs.release()
    return cam, units


def check(vpcal, calib_path, tmp):
    doc = json.load(open(calib_path))
    cam, units = from_yaml(vpcal, calib_path, tmp)
    block = doc["opencv"]
    for k, j in (("camera_matrix", "camera_matrix"), ("distortion_coefficients", "dist_coeffs"),
                 ("rvec", "rvec"), ("tvec", "tvec")):
        if not np.array_equal(cam[k].reshape(-1), np.array(block[j], dtype=np.float64).reshape(-1)):
            sys.exit(f"FAIL: {k} of the YAML file differs from calib.json's opencv.{j}")
    if units != block["units"]:
        sys.exit(f"FAIL: units {units!r} vs {block['units']!r}")
    cv = {"camera_matrix": cam["camera_matrix"], "dist_coeffs": cam["distortion_coefficients"],
          "rvec": cam["rvec"], "tvec": cam["tvec"], "units": units}
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
    with tempfile.TemporaryDirectory() as tmp:
        worst = check(a.vpcal, a.calib, tmp)
        scaled = f"{tmp}/scaled.json"
        shutil.copy(a.calib, scaled)
        doc = json.load(open(scaled))
        w, h = doc["image_size"]
        # Any road distance makes a scale; these two pixels are on the road below the horizon.
        subprocess.run([a.vpcal, "scale", scaled, "--points",
                        f"{w * 0.4},{h * 0.9},{w * 0.6},{h * 0.9}", "--distance", "3.5"],
                       check=True, capture_output=True)
        worst = max(worst, check(a.vpcal, scaled, tmp))
    if worst > 1e-6:
        sys.exit(f"FAIL: {worst:.2e} > 1e-6")
    print("OK: cv2.projectPoints and vpcal measure agree")


if __name__ == "__main__":
    main()
