#!/usr/bin/env python3
"""Count the vehicle boxes whose bottom centre lies above a calibration's horizon.

Vehicles stand on the road, so a valid calibration has every box below its horizon (the line
through vp1 and vp2). On the synthetic suite every catastrophic result (ratio error > 300 %)
so far had most boxes above the horizon, and every other result had none.

Usage: scripts/horizon_vs_boxes.py SUITE_DIR [RESULTS_SUBDIR] [SYSTEM ...]
  SUITE_DIR       rendered by `vpcal synth suite` (dataset/<scene>/detections.csv)
  RESULTS_SUBDIR  folder under SUITE_DIR with <scene>/system_<name>.json (default: results)
  SYSTEM          system names (default: groundtruth vpcal_trueboxes vpcal_motion)
Needs only the Python standard library.
"""
import csv
import json
import os
import sys


def side(vp1, vp2, p):
    """Sign of p relative to the line vp1 -> vp2."""
    dx, dy = vp2[0] - vp1[0], vp2[1] - vp1[1]
    c = dx * (p[1] - vp1[1]) - dy * (p[0] - vp1[0])
    return (c > 0) - (c < 0)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    suite = sys.argv[1]
    results = sys.argv[2] if len(sys.argv) > 2 else "results"
    systems = sys.argv[3:] or ["groundtruth", "vpcal_trueboxes", "vpcal_motion"]
    for scene in sorted(os.listdir(os.path.join(suite, "dataset"))):
        det = os.path.join(suite, "dataset", scene, "detections.csv")
        with open(det, newline="") as f:
            rows = list(csv.DictReader(f))
        bottoms = [((float(r["x0"]) + float(r["x1"])) / 2, float(r["y1"])) for r in rows]
        for name in systems:
            path = os.path.join(suite, results, scene, f"system_{name}.json")
            if not os.path.isfile(path):
                print(f"{scene:22s} {name:16s} missing")
                continue
            with open(path) as f:
                cal = json.load(f)["camera_calibration"]
            vp1, vp2, pp = cal["vp1"], cal["vp2"], cal["pp"]
            below = side(vp1, vp2, (pp[0], pp[1] + 1e7))
            above = sum(1 for p in bottoms if side(vp1, vp2, p) != below)
            print(f"{scene:22s} {name:16s} {above:6d} of {len(bottoms)} boxes above the horizon")


if __name__ == "__main__":
    main()
