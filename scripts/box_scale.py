#!/usr/bin/env python3
"""How large does each detector box say its vehicle is, at a calibration whose scale is known?

A check of the automatic scale (`scale_source: vehicles`) on real footage: scale a calibration
from something else first (e.g. `vpcal scale calib.json --lane-points ... --lane-width 3.6`),
then every box (a `vpcal detect -o` CSV) gets the cuboid of a typical 4.4 x 1.8 x 1.5 m car on
the road along VP1 (road x, y and a size factor, least squares on the four box sides, as
vpcal_geom::vehicle_scale does). A size of 1 means the box reads as exactly the typical car
at the known scale; the automatic scale is off by the inverse of the median. Printed: the
median over boxes that fit (RMS misfit <= 6 % of the diagonal), and by box width.

Needs numpy and scipy. Usage: python3 scripts/box_scale.py SCALED_CALIB.json BOXES.csv
"""
import json
import sys

import numpy as np
from scipy.optimize import minimize

cal = json.load(open(sys.argv[1]))
boxes = np.loadtxt(sys.argv[2], delimiter=',', skiprows=1)
K, R, h = np.array(cal['K']), np.array(cal['R']), cal['camera_height_m']
W, H = cal['image_size']
DIMS = np.array([4.4, 1.8, 1.5])
CORNERS = np.array([[a, w, z] for a in (-.5, .5) for w in (-.5, .5) for z in (0, 1)])


def project(X):
    """Road points (metres, z up) to pixels: R's columns are the road axes in camera axes."""
    c = X[:, 0:1] * R[:, 0] + X[:, 1:2] * R[:, 1] + (h - X[:, 2:3]) * R[:, 2]
    p = (K @ c.T).T
    return p[:, :2] / p[:, 2:3]


def road(px):
    d = np.linalg.solve(K, [px[0], px[1], 1.0])
    c = h / (d @ R[:, 2]) * d
    return np.array([c @ R[:, 0], c @ R[:, 1]])


def cuboid_box(x, y, s):
    X = CORNERS * DIMS * s
    X[:, 0] += x
    X[:, 1] += y
    p = project(X)
    return np.r_[p.min(0), p.max(0)]


rows = []
for _, x0, y0, x1, y1, _ in boxes:
    if x0 < 2 or y0 < 2 or x1 > W - 2 or y1 > H - 2:
        continue
    b = np.array([x0, y0, x1, y1])
    d2 = (x1 - x0) ** 2 + (y1 - y0) ** 2
    q = road(((x0 + x1) / 2, y1))
    best = None
    for s0 in (0.5, 1.0, 2.0):
        m = minimize(lambda p: ((cuboid_box(p[0], p[1], np.exp(p[2])) - b) ** 2).sum() / d2,
                     [q[0], q[1], np.log(s0)], method='Nelder-Mead', options={'maxiter': 600})
        if best is None or m.fun < best.fun:
            best = m
    rows.append((x1 - x0, np.exp(best.x[2]), np.sqrt(best.fun / 4)))
rows = np.array(rows)
ok = rows[:, 2] <= 0.06
print(f'boxes {len(rows)}, fit {ok.sum()}, median size {np.median(rows[ok, 1]):.2f} '
      '(1: the typical car at the known scale)')
for lo, hi in [(0, 15), (15, 25), (25, 40), (40, 10000)]:
    s = ok & (rows[:, 0] >= lo) & (rows[:, 0] < hi)
    if s.sum():
        print(f'  box width {lo}-{hi} px: {s.sum()} boxes, size median {np.median(rows[s, 1]):.2f} '
              f'(quartiles {np.percentile(rows[s, 1], 25):.2f}-{np.percentile(rows[s, 1], 75):.2f})')
