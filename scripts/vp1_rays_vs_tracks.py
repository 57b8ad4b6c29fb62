#!/usr/bin/env python3
"""Per scene of a synthetic suite: how well the network's per-vehicle VP1 rays and the
vehicles' box-centre tracks point at the true VP1.

Usage: scripts/vp1_rays_vs_tracks.py SUITE_DIR VEHICLES_DIR
  SUITE_DIR     rendered by `vpcal synth suite` (dataset/<scene>/vehicles.jsonl holds the true
                boxes with vehicle ids and true VPs)
  VEHICLES_DIR  <scene>.json per scene, written by
                `vpcal calibrate SUITE_DIR/dataset/<scene>/video.mp4 \
                   --detections SUITE_DIR/dataset/<scene>/detections.csv --vehicles <scene>.json`
Angles are signed (degrees) between a line and the direction to the true VP1; a track's line is
the total-least-squares line through its box centres (tracks of 8+ boxes that moved 30+ px).
"""
import json
import math
import os
import sys

import numpy as np


def line_angle(d, t):
    a = math.degrees(math.atan2(d[0] * t[1] - d[1] * t[0], d @ t))
    return (a + 90.0) % 180.0 - 90.0


def summary(errors):
    e = np.array(errors)
    if len(e) == 0:
        return "   n    0"
    return f"n {len(e):4d} mean {e.mean():+6.2f} median {np.median(e):+6.2f} |median| {np.median(abs(e)):5.2f}"


def main(suite, vehicles_dir):
    for scene in sorted(os.listdir(os.path.join(suite, "dataset"))):
        truth = {}
        tracks = {}
        for line in open(os.path.join(suite, "dataset", scene, "vehicles.jsonl")):
            v = json.loads(line)
            truth.setdefault(v["frame"], []).append(v)
            tracks.setdefault(v["id"], []).append(v)
        rays = []
        path = os.path.join(vehicles_dir, scene + ".json")
        if os.path.exists(path):
            for item in json.load(open(path)):
                c = np.array(item["box_center"])
                cands = truth.get(int(item["frame_cnt"]), [])
                if not cands or not all(math.isfinite(x) for x in item["vp1"]):
                    continue
                best = min(cands, key=lambda v: np.hypot((v["box"][0] + v["box"][2]) / 2 - c[0],
                                                         (v["box"][1] + v["box"][3]) / 2 - c[1]))
                rays.append(line_angle(np.array(item["vp1"]) - c, np.array(best["vp1"]) - c))
        lines = []
        for vs in tracks.values():
            b = np.array([v["box"] for v in vs])
            p = np.c_[(b[:, 0] + b[:, 2]) / 2, (b[:, 1] + b[:, 3]) / 2]
            if len(vs) < 8 or np.linalg.norm(p[-1] - p[0]) < 30:
                continue
            m = p.mean(0)
            d = np.linalg.svd(p - m)[2][0]
            lines.append(line_angle(d, np.array(vs[len(vs) // 2]["vp1"]) - m))
        print(f"{scene:22s} network rays: {summary(rays)} | tracks: {summary(lines)}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
