#!/usr/bin/env python3
"""Independent computation of the BrnoCompSpeed pure-calibration ratio error.

Written from the published protocol (Sochor et al., BrnoCompSpeed; DESIGN.md §3 and §8) with
numpy, independently of vpcal's Rust code, to produce the expected numbers that
`crates/vpcal/tests/cli.rs` checks `vpcal eval bcs` against.

For each video: camera from the system file's vp1, vp2, pp (focal from orthogonality, road
plane normal from vp3, plane n.X + 10 = 0, camera centre (px, py, 0)); every unordered pair of
ground-truth distance measurements (i < j) gives |d^_i/d^_j - d_i/d_j| / (d_i/d_j) * 100.

Usage: python3 scripts/bcs_ratio_errors.py DATASET_DIR RESULTS_DIR SYSTEM_NAME
Needs numpy (pickle's gt_data.pkl holds numpy arrays): a throwaway venv is enough.
Prints one JSON line per video: name, pairs, mean, median, p95, max.
"""
import json
import os
import pickle
import sys

import numpy as np


def road_point(p, pp, focal, normal):
    p = np.asarray(p, dtype=float)
    if p.shape[0] == 3:
        p = p[:2] / p[2]
    centre = np.array([pp[0], pp[1], 0.0])
    ray = np.array([p[0] - pp[0], p[1] - pp[1], focal])
    t = -(normal @ centre + 10.0) / (normal @ ray)
    return centre + t * ray


def camera(vp1, vp2, pp):
    vp1, vp2, pp = (np.asarray(v, dtype=float) for v in (vp1, vp2, pp))
    focal = np.sqrt(-np.dot(vp1 - pp, vp2 - pp))
    d3 = np.cross(np.append(vp1 - pp, focal), np.append(vp2 - pp, focal))
    vp3 = d3[:2] / d3[2] * focal + pp
    normal = np.append(vp3 - pp, focal)
    return focal, normal / np.linalg.norm(normal)


def main():
    dataset, results, system = sys.argv[1:4]
    for video in sorted(os.listdir(dataset)):
        gt_path = os.path.join(dataset, video, "gt_data.pkl")
        sys_path = os.path.join(results, video, "system_%s.json" % system)
        if not (os.path.isfile(gt_path) and os.path.isfile(sys_path)):
            continue
        with open(gt_path, "rb") as f:
            gt = pickle.load(f, encoding="latin-1")
        with open(sys_path) as f:
            calib = json.load(f)["camera_calibration"]
        focal, normal = camera(calib["vp1"], calib["vp2"], calib["pp"])
        meas = gt["distanceMeasurement"]
        est = [np.linalg.norm(road_point(m["p1"], calib["pp"], focal, normal)
                              - road_point(m["p2"], calib["pp"], focal, normal)) for m in meas]
        errors = []
        for i in range(len(meas)):
            for j in range(i + 1, len(meas)):
                truth = meas[i]["distance"] / meas[j]["distance"]
                errors.append(abs(est[i] / est[j] - truth) / truth * 100.0)
        errors = np.array(errors)
        print(json.dumps({
            "video": video, "pairs": int(errors.size), "mean": float(errors.mean()),
            "median": float(np.median(errors)), "p95": float(np.percentile(errors, 95)),
            "max": float(errors.max())}))


if __name__ == "__main__":
    main()
