#!/usr/bin/env python3
"""Which point of a real detector's box travels towards VP1: BrnoCompSpeed sessions 0-3.

Each video's `detections.json` (deep_vp's detector, every 10th frame of a 50 fps video; boxes
`[ymin, xmin, ymax, xmax]` normalised to 1920x1080) is linked into tracks (greedy, by the
overlap of a box with where the track's last box is predicted at constant image velocity;
tracks of at least 6 boxes whose bottom centre moved at least 60 px). Per track, a
total-least-squares line through the point (x centre, y0 + t · height) of its boxes, for
t = 0 (top), 0.25, 0.5 (the centre, what vpcal's VP1 tracks use), 0.75 and 1 (bottom), is
compared with the reference VP1 of `camera_truth.json` (from the lane dividers):
- the signed angle at the track between its line and the direction to the reference VP1;
- VP1 from all of a video's lines (Cauchy-weighted least squares), its distance from the
  reference VP1 in percent of the reference's distance from the principal point.
A fixed point of a vehicle driving straight moves on a line through VP1; a box's centre is not
a fixed point of the vehicle (the outline seen changes as the view does).

Usage: scripts/bcs_track_vp1.py [MIN_SCORE]    (default 0.5; data from $VPCAL_DATA/bcs)
"""
import json
import math
import os
import sys

import numpy as np

from track_sizes import iou

DATA = os.environ.get("VPCAL_DATA", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"))
TS = [0.0, 0.25, 0.5, 0.75, 1.0]
W, H = 1920, 1080
PP = np.array([960.5, 540.5])
MAX_GAP = 30  # frames between a track's boxes
MIN_BOXES = 6
MIN_MOVE_PX = 60


def link(detections, min_score):
    """Tracks as lists of (frame, [x0, y0, x1, y1]) in pixels."""
    tracks, active = [], []
    for item in detections:
        frame = item["frame_cnt"]
        boxes = [[b[1] * W, b[0] * H, b[3] * W, b[2] * H]
                 for b, s in zip(item["boxes"], item["scores"]) if s >= min_score]
        pairs = []
        for ti in active:
            t = tracks[ti]
            last_frame, last = t[-1]
            if frame - last_frame > MAX_GAP:
                continue
            pred = last
            if len(t) >= 2:
                prev_frame, prev = t[-2]
                k = (frame - last_frame) / (last_frame - prev_frame)
                pred = [last[i] + k * (last[i] - prev[i]) for i in range(4)]
            for j, b in enumerate(boxes):
                o = iou(pred, b)
                if o > 0.3:
                    pairs.append((o, ti, j))
        pairs.sort(reverse=True)
        taken_tracks, taken_boxes = set(), set()
        for _, ti, j in pairs:
            if ti in taken_tracks or j in taken_boxes:
                continue
            tracks[ti].append((frame, boxes[j]))
            taken_tracks.add(ti)
            taken_boxes.add(j)
        active = [ti for ti in active if frame - tracks[ti][-1][0] <= MAX_GAP]
        for j, b in enumerate(boxes):
            if j not in taken_boxes:
                tracks.append([(frame, b)])
                active.append(len(tracks) - 1)
    return tracks


def line(points):
    """Unit normal n and offset c of the TLS line n·p = c, and the points' centroid."""
    c = points.mean(0)
    _, _, vt = np.linalg.svd(points - c)
    d = vt[0]
    n = np.array([-d[1], d[0]])
    return n, n @ c, c, d


def signed_angle(points, vp):
    _, _, c, d = line(points)
    v = np.asarray(vp) - c
    if d @ v < 0:
        d = -d
    return math.degrees(math.atan2(d[0] * v[1] - d[1] * v[0], d @ v))


def intersection(lines, start):
    x = np.asarray(start, float)
    a = np.array([n for n, _ in lines])
    b = np.array([c for _, c in lines])
    for _ in range(50):
        r = a @ x - b
        scale = np.median(np.abs(r)) + 1e-6
        w = np.sqrt(1.0 / (1.0 + (r / (2.0 * scale)) ** 2))
        x = np.linalg.lstsq(a * w[:, None], b * w, rcond=None)[0]
    return x


def main():
    min_score = float(sys.argv[1]) if len(sys.argv) > 1 else 0.5
    cameras = json.load(open(os.path.join(DATA, "bcs", "camera_truth.json")))["cameras"]
    angles = {t: [] for t in TS}
    vp_errors = {t: [] for t in TS}
    print(f"{'video':<18} {'tracks':>6}  " + "  ".join(f"t={t:.2f}: angle, |angle|, VP1 %" for t in TS))
    for name in sorted(cameras):
        path = os.path.join(DATA, "bcs", "dataset", name, "detections.json")
        if not os.path.exists(path):
            continue
        vp = np.asarray(cameras[name]["vp1"])
        tracks = []
        for t in link(json.load(open(path)), min_score):
            if len(t) < MIN_BOXES:
                continue
            b = np.array([box for _, box in t])
            cx = (b[:, 0] + b[:, 2]) / 2
            if math.hypot(cx[-1] - cx[0], b[-1, 3] - b[0, 3]) >= MIN_MOVE_PX:
                tracks.append((cx, b))
        if len(tracks) < 2:
            print(f"{name:<18} {len(tracks):>6}  (too few tracks)")
            continue
        cells = []
        for t in TS:
            pts = [np.c_[cx, b[:, 1] + t * (b[:, 3] - b[:, 1])] for cx, b in tracks]
            a = [signed_angle(p, vp) for p in pts]
            est = intersection([line(p)[:2] for p in pts], vp + 5.0)
            err = 100.0 * np.linalg.norm(est - vp) / np.linalg.norm(vp - PP)
            angles[t] += a
            vp_errors[t].append(err)
            cells.append(f"{np.median(a):+6.2f} {np.median(np.abs(a)):5.2f} {err:6.1f}")
        print(f"{name:<18} {len(tracks):>6}  " + "  ".join(cells))
    print(f"{'all':<18} {len(angles[0.5]):>6}  " + "  ".join(
        f"{np.median(angles[t]):+6.2f} {np.median(np.abs(angles[t])):5.2f} {np.median(vp_errors[t]):6.1f}"
        for t in TS) + "   (VP1 %: median over videos)")


if __name__ == "__main__":
    main()
