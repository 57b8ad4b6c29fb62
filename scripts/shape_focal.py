#!/usr/bin/env python3
"""Can the vehicles' box shapes tell the focal length? (issue 17, "vehicle shape"; a
measurement, not part of vpcal.)

For a candidate focal length f (VP1, horizon angle and principal point fixed, the camera one
unit above the road) every detector box gets the cuboid of a typical car (4.4 x 1.8 x 1.5 m
proportions) standing on the road along VP1, with its height free: road x, y, size and a height
factor fit the box's four sides exactly. The median ln(height factor) over the boxes, as a
function of f, is printed per video: if box shapes pinned f, it would cross a fixed value at
the true f.

BrnoCompSpeed sessions 0-3 (VPCAL_DATA/bcs): the dataset's detections.json boxes (score >= 0.5,
150 per video, away from the border) and the reference camera of camera_truth.json; f on a
grid of 0.4-2.5 x the reference focal length. `--calib C --boxes CSV`: one calibration file
(its VP1, horizon and pp) and a CSV of boxes (`vpcal detect -o`), f from 300 to 8000 px.

Needs numpy and scipy. Usage:
  python3 scripts/shape_focal.py                      # BCS sessions 0-3
  python3 scripts/shape_focal.py --calib calib.json --boxes boxes.csv
"""
import argparse
import json
import os

import numpy as np
from scipy.optimize import least_squares

DIMS = np.array([4.4, 1.8, 1.5])
CORNERS = np.array([[a, w, z] for a in (-.5, .5) for w in (-.5, .5) for z in (0, 1)])


def camera(pp, vp1, horizon_deg, f):
    """K and the road frame (VP1 direction, across, normal towards the road) in camera axes."""
    K = np.array([[f, 0, pp[0]], [0, f, pp[1]], [0, 0, 1.0]])
    d1 = np.array([vp1[0] - pp[0], vp1[1] - pp[1], f])
    d1 /= np.linalg.norm(d1)
    t = np.radians(horizon_deg)
    line = np.cross([vp1[0], vp1[1], 1.0], [vp1[0] + np.cos(t), vp1[1] + np.sin(t), 1.0])
    n = K.T @ line
    n /= np.linalg.norm(n)
    if n[1] < 0:
        n = -n
    n -= (n @ d1) * d1
    n /= np.linalg.norm(n)
    return K, d1, np.cross(n, d1), n


def road(cam, px):
    K, d1, d2, n = cam
    d = np.linalg.solve(K, [px[0], px[1], 1.0])
    den = d @ n
    if den <= 1e-9:
        return None
    c = d / den
    return np.array([c @ d1, c @ d2])


def height_factor(cam, box):
    """ln(height factor) of the car cuboid whose image bounding box is `box`; None on misfit."""
    K, d1, d2, n = cam
    q = road(cam, ((box[0] + box[2]) / 2, box[3]))
    ql, qr = road(cam, (box[0], box[3])), road(cam, (box[2], box[3]))
    if q is None or ql is None or qr is None:
        return None
    across = np.linalg.norm(ql - qr)
    diag = np.hypot(box[2] - box[0], box[3] - box[1])

    def residual(p):
        dims = DIMS * np.exp(p[2]) * np.array([1, 1, np.exp(p[3])])
        X = CORNERS * dims
        X[:, 0] += p[0]
        X[:, 1] += p[1]
        c = X[:, 0:1] * d1 + X[:, 1:2] * d2 + (1.0 - X[:, 2:3]) * n
        if (c[:, 2] <= 0).any():
            return np.full(4, 10.0)
        pr = (K @ c.T).T
        pr = pr[:, :2] / pr[:, 2:3]
        return (np.r_[pr.min(0), pr.max(0)] - box) / diag

    best = None
    for k in (0.5, 1.0):
        s0 = across / DIMS[1] * k
        r = least_squares(residual, [q[0] + 0.5 * s0 * DIMS[0], q[1], np.log(s0), 0.0],
                          method='lm', max_nfev=300)
        if best is None or r.cost < best.cost:
            best = r
    return best.x[3] if np.sqrt(2 * best.cost / 4) <= 0.02 else None


def curve(pp, vp1, horizon_deg, boxes, grid):
    out = []
    for f in grid:
        cam = camera(pp, vp1, horizon_deg, f)
        a = [v for v in (height_factor(cam, b) for b in boxes) if v is not None]
        out.append((f, float(np.median(a)) if a else float('nan'), len(a)))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--calib')
    ap.add_argument('--boxes')
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    if a.calib:
        cal = json.load(open(a.calib))
        w, h = cal['image_size']
        b = np.loadtxt(a.boxes, delimiter=',', skiprows=1)
        b = b[b[:, 5] > 0.4][:, 1:5]
        b = b[(b[:, 0] > 3) & (b[:, 1] > 3) & (b[:, 2] < w - 3) & (b[:, 3] < h - 3)
              & (b[:, 2] - b[:, 0] > 12)]
        b = b[rng.choice(len(b), min(150, len(b)), replace=False)]
        grid = np.exp(np.linspace(np.log(300), np.log(8000), 16))
        c = curve(cal['pp'], cal['vp1'], cal['horizon']['angle_deg'], b, grid)
        print(' '.join(f'{f:.0f}:{m:+.2f}/{n}' for f, m, n in c))
        return
    data = os.environ.get('VPCAL_DATA', '../shared/data')
    truth = json.load(open(f'{data}/bcs/camera_truth.json'))['cameras']
    print('video: f/f_ref:median ln(height factor)/boxes fitted')
    for v, t in sorted(truth.items()):
        boxes = []
        for fr in json.load(open(f'{data}/bcs/dataset/{v}/detections.json')):
            for bb, s in zip(fr['boxes'], fr['scores']):
                y0, x0, y1, x1 = bb
                px = np.array([x0 * 1920, y0 * 1080, x1 * 1920, y1 * 1080])
                if s >= 0.5 and px[0] >= 10 and px[1] >= 10 and px[2] <= 1910 and px[3] <= 1070:
                    boxes.append(px)
        boxes = np.array(boxes)
        boxes = boxes[rng.choice(len(boxes), min(150, len(boxes)), replace=False)]
        grid = t['focal_px'] * np.exp(np.linspace(np.log(0.4), np.log(2.5), 15))
        c = curve(t['pp'], t['vp1'], t['horizon_angle_deg'], boxes, grid)
        print(v, f"f_ref {t['focal_px']:.0f}",
              ' '.join(f'{f / t["focal_px"]:.2f}:{m:+.2f}/{n}' for f, m, n in c), flush=True)


if __name__ == '__main__':
    main()
