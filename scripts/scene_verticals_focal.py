#!/usr/bin/env python3
"""The focal length from the scene's vertical lines (VP3), where the camera is known.

Poles, posts, walls and buildings stand vertical, so their image lines meet at VP3, the road
normal's vanishing point. Given VP1 and the horizon through it, VP3 lies on the normal from
the principal point to the horizon at f^2 / d (d: the principal point's distance from the
horizon), so VP3 measures f without VP2. This fits it to the scene's edgelets (those not
pointing at VP1), as a 1-D search over ln f with the horizon's roll free (the verticals set
their own tilt), the edgelets within 6, 3, 1.5 and 0.75 degrees of the current VP3 direction
in turn, started from the physical prior's middle (1.38 widths); a fit that ends at the
search's end (0.3 or 8 widths) is not identified. VP1 and the horizon are the truth's.

  scripts/scene_verticals_focal.py bcs            BrnoCompSpeed sessions 0-3: each screen.png
                                                  (unmasked, as calibrate sees the frame),
                                                  against camera_truth.json
  scripts/scene_verticals_focal.py suite SUITE    the synthetic suite (SUITE from
                                                  `vpcal synth suite`): calibrate's
                                                  --scene-edgelets of each scene, against its
                                                  camera.json

Needs numpy and scipy. VPCAL: the binary for the suite (default target/release/vpcal).
"""
import glob
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.optimize import minimize

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
DATA = os.environ.get("VPCAL_DATA", os.path.join(ROOT, "..", "shared", "data"))
PRIOR_WIDTHS = 1.38
SEARCH_WIDTHS = (0.3, 8.0)


def line_diff(a):
    return (a + np.pi / 2) % np.pi - np.pi / 2


def vp3(vp1, roll, pp, f):
    h = np.array([math.cos(roll), math.sin(roll)])
    foot = vp1 + np.dot(pp - vp1, h) * h
    dv = pp - foot
    d = np.linalg.norm(dv)
    return pp + dv / d * f * f / d


def fit(e, vp1, roll0, pp, width):
    x, y, ang, s = e[:, 0], e[:, 1], e[:, 2], e[:, 3]
    keep = np.abs(line_diff(ang - np.arctan2(vp1[1] - y, vp1[0] - x))) > math.radians(1.0)
    x, y, ang, s = x[keep], y[keep], ang[keep], s[keep]
    lo, hi = (math.log(w * width) for w in SEARCH_WIDTHS)
    p = np.array([math.log(PRIOR_WIDTHS * width), roll0])
    for tol in np.radians([6, 3, 1.5, 0.75]):
        v = vp3(vp1, p[1], pp, math.exp(p[0]))
        m = np.abs(line_diff(ang - np.arctan2(v[1] - y, v[0] - x))) < tol
        X, Y, A, S = x[m], y[m], ang[m], s[m]

        def cost(q):
            lf = min(max(q[0], lo), hi)
            v = vp3(vp1, q[1], pp, math.exp(lf))
            r = line_diff(A - np.arctan2(v[1] - Y, v[0] - X)) / (tol / 2)
            return np.sum(S * np.log1p(r * r)) + 1e3 * (q[0] - lf) ** 2

        grid = np.linspace(lo, hi, 80)
        g0 = grid[int(np.argmin([cost([g, p[1]]) for g in grid]))]
        p = minimize(cost, [g0, p[1]], method="Nelder-Mead",
                     options={"xatol": 1e-6, "fatol": 1e-8, "maxiter": 3000}).x
        p[0] = min(max(p[0], lo), hi)
    at_end = p[0] <= lo + 1e-6 or p[0] >= hi - 1e-6
    return math.exp(p[0]), p[1], int(m.sum()), at_end


def report(rows):
    ratios = []
    for name, true_f, f, d_roll, used, at_end in rows:
        print(f"{name:22s} true {true_f:6.0f}  fit {f:6.0f}  ratio {f / true_f:5.2f}  roll - horizon's "
              f"{math.degrees(d_roll):6.2f} deg  edgelets {used:6d}  {'not identified' if at_end else ''}")
        if not at_end:
            ratios.append(f / true_f)
    r = np.array(ratios)
    print(f"identified {len(r)} of {len(rows)}: ratio median {np.median(r):.2f}, |ln ratio| median "
          f"{np.median(np.abs(np.log(r))):.3f}, rms {math.sqrt(np.mean(np.log(r) ** 2)):.3f}")


def bcs():
    subprocess.run(["cargo", "build", "--release", "--quiet", "--example", "scene_edgelets"], cwd=ROOT, check=True)
    example = os.path.join(ROOT, "target", "release", "examples", "scene_edgelets")
    cameras = json.load(open(os.path.join(DATA, "bcs", "camera_truth.json")))["cameras"]
    rows = []
    for name, c in cameras.items():
        screen = os.path.join(DATA, "bcs", "dataset", name, "screen.png")
        e = np.array(json.loads(subprocess.run([example, screen], check=True, capture_output=True,
                                               text=True).stdout))
        vp1, vp2, pp = (np.array(c[k]) for k in ("vp1", "vp2", "pp"))
        true_f = math.sqrt(-np.dot(vp1 - pp, vp2 - pp))
        roll = math.atan2(vp2[1] - vp1[1], vp2[0] - vp1[0])
        f, r, used, at_end = fit(e, vp1, roll, pp, 1920.0)
        rows.append((name, true_f, f, r - roll, used, at_end))
    report(rows)


def suite(folder):
    vpcal = os.environ.get("VPCAL", os.path.join(ROOT, "target", "release", "vpcal"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for d in sorted(glob.glob(os.path.join(folder, "dataset", "*/"))):
            name = os.path.basename(d.rstrip("/"))
            scene = os.path.join(tmp, name + ".scene.json")
            subprocess.run([vpcal, "calibrate", os.path.join(d, "video.mp4"), "--detections",
                            os.path.join(d, "detections.csv"), "--quiet", "-o", os.path.join(tmp, name + ".json"),
                            "--scene-edgelets", scene], capture_output=True)
            cam = json.load(open(os.path.join(d, "camera.json")))
            e = np.array(json.load(open(scene))["edgelets"]) if os.path.exists(scene) else np.zeros((0, 4))
            if len(e) == 0:
                print(f"{name:22s} no scene edgelets")
                continue
            vp1, vp2, pp = (np.array(cam[k]) for k in ("vp1", "vp2", "pp"))
            roll = math.atan2(vp2[1] - vp1[1], vp2[0] - vp1[0])
            f, r, used, at_end = fit(e, vp1, roll, pp, float(cam["width"]))
            rows.append((name, cam["focal_px"], f, r - roll, used, at_end))
    report(rows)


if __name__ == "__main__":
    if len(sys.argv) >= 2 and sys.argv[1] == "bcs":
        bcs()
    elif len(sys.argv) >= 3 and sys.argv[1] == "suite":
        suite(sys.argv[2])
    else:
        sys.exit(__doc__)
