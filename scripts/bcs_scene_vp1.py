#!/usr/bin/env python3
"""VP1 from the scene's lines on real views: BrnoCompSpeed sessions 0-3.

Each video's `screen.png` (one real 1080p frame; `video_mask.png` leaves out what is not the
scene) goes through the calibration's scene-line fit (`cargo run --release --example
scene_vp1`: the edgelets of the picture, moved from a start to where those pointing at it
meet), compared with the reference VP1 of `camera_truth.json` (fitted to the annotated lane
dividers). Errors are in percent of the reference VP1's distance from the principal point.

1. From the VP1 of the video's vehicle tracks: deep_vp's detections linked into tracks as in
   `bcs_track_vp1.py` (box centres; the tracks' VP1 from their lines, started from two of
   them, not from the reference), then the scene lines from there. Also the median angle of
   the track lines at their own VP1 and at the scene lines' one (the calibration uses the scene
   lines' VP1 only while that rises by at most `scene_max_extra_deg`, 2.5°).
2. From starts around the reference VP1 (8 directions, 2-20 % of its distance off): where the
   fit ends, and how often within 3 %.

Usage: scripts/bcs_scene_vp1.py     (data from $VPCAL_DATA/bcs; builds the example first)
"""
import json
import math
import os
import subprocess
import sys

import numpy as np

from bcs_track_vp1 import DATA, MIN_BOXES, MIN_MOVE_PX, PP, intersection, line, link, signed_angle

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
EXAMPLE = os.path.join(ROOT, "target", "release", "examples", "scene_vp1")
MAX_EXTRA_DEG = 2.5


def scene_vp1(folder, start):
    out = subprocess.run([EXAMPLE, os.path.join(folder, "screen.png"), f"{start[0]:.3f},{start[1]:.3f}",
                          os.path.join(folder, "video_mask.png")], check=True, capture_output=True, text=True)
    r = json.loads(out.stdout)
    return (np.array(r["vp1"]) if r["vp1"] else None), r["edgelets"]


def track_points(folder):
    tracks = []
    for t in link(json.load(open(os.path.join(folder, "detections.json"))), 0.5):
        if len(t) < MIN_BOXES:
            continue
        b = np.array([box for _, box in t])
        cx = (b[:, 0] + b[:, 2]) / 2
        if math.hypot(cx[-1] - cx[0], b[-1, 3] - b[0, 3]) >= MIN_MOVE_PX:
            tracks.append(np.c_[cx, (b[:, 1] + b[:, 3]) / 2])
    return tracks


def median_angle(tracks, vp):
    return float(np.median([abs(signed_angle(p, vp)) for p in tracks]))


def main():
    subprocess.run(["cargo", "build", "--release", "--quiet", "--example", "scene_vp1"], cwd=ROOT, check=True)
    cameras = json.load(open(os.path.join(DATA, "bcs", "camera_truth.json")))["cameras"]
    print("1. from the tracks' VP1 (box centres of deep_vp's detections)")
    print(f"{'video':<16} {'tracks':>6} {'tracks %':>8} {'scene %':>8} {'edgelets':>8} "
          f"{'angle own':>9} {'at scene':>8} {'used':>5} {'final %':>8}")
    before, after = [], []
    for name in sorted(cameras):
        folder = os.path.join(DATA, "bcs", "dataset", name)
        vp = np.asarray(cameras[name]["vp1"])
        dist = np.linalg.norm(vp - PP)
        tracks = track_points(folder)
        if len(tracks) < 5:
            print(f"{name:<16} {len(tracks):>6}  (fewer than 5 tracks: VP1 would come from the network)")
            continue
        lines = [line(p)[:2] for p in tracks]
        longest = sorted(range(len(tracks)), key=lambda i: -len(tracks[i]))[:2]
        (n0, c0), (n1, c1) = lines[longest[0]], lines[longest[1]]
        start = np.linalg.solve(np.array([n0, n1]), np.array([c0, c1]))
        own = intersection(lines, start)
        fit, used = scene_vp1(folder, own)
        a_own = median_angle(tracks, own)
        a_fit = median_angle(tracks, fit) if fit is not None else float("nan")
        ok = fit is not None and a_fit - a_own <= MAX_EXTRA_DEG
        final = fit if ok else own
        e = lambda q: 100 * np.linalg.norm(q - vp) / dist
        before.append(e(own))
        after.append(e(final))
        print(f"{name:<16} {len(tracks):>6} {e(own):>8.1f} {e(fit) if fit is not None else float('nan'):>8.1f} "
              f"{used:>8} {a_own:>9.2f} {a_fit:>8.2f} {'yes' if ok else 'no':>5} {e(final):>8.1f}")
    print(f"{'median':<16} {'':>6} {np.median(before):>8.1f} {'':>8} {'':>8} {'':>9} {'':>8} {'':>5} "
          f"{np.median(after):>8.1f}")
    print("\n2. from starts around the reference VP1 (8 directions): median / max error %, share within 3 %")
    fracs = [0.02, 0.05, 0.1, 0.2]
    print(f"{'video':<16} " + "  ".join(f"{f:>5.0%} off: med   max  <3%" for f in fracs))
    pooled = {f: [] for f in fracs}
    for name in sorted(cameras):
        folder = os.path.join(DATA, "bcs", "dataset", name)
        vp = np.asarray(cameras[name]["vp1"])
        dist = np.linalg.norm(vp - PP)
        cells = []
        for f in fracs:
            errs = []
            for k in range(8):
                a = k * math.pi / 4 + 0.3
                fit, _ = scene_vp1(folder, vp + f * dist * np.array([math.cos(a), math.sin(a)]))
                errs.append(100 * np.linalg.norm(fit - vp) / dist if fit is not None else float("inf"))
            pooled[f] += errs
            errs = np.array(errs)
            cells.append(f"{np.median(errs):>14.2f} {np.max(errs):>5.1f} {np.mean(errs < 3):>4.0%}")
        print(f"{name:<16} " + "  ".join(cells))
    print(f"{'all':<16} " + "  ".join(
        f"{np.median(pooled[f]):>14.2f} {np.max(pooled[f]):>5.1f} {np.mean(np.array(pooled[f]) < 3):>4.0%}" for f in fracs))


if __name__ == "__main__":
    sys.exit(main())
