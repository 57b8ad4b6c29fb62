#!/usr/bin/env python3
"""The network's VP2 rays on rendered scenes with known cameras, vehicle by vehicle.

For each scene folder (`vpcal synth scene` or `vpcal synth suite` output: video.mp4,
detections.csv, camera.json), runs `vpcal calibrate --detections detections.csv --vehicles`
and reads every record the network saw (not the copied ones):
- the signed turn of its VP2 ray from the true VP2's direction, degrees, positive when turned
  (the smaller way) towards the direction of the true VP1, as `vpcal eval kitti` prints it;
- where its ray meets the true horizon, as the focal length that point would give with the
  true VP1 (median of ln(f_i / f)): whether the rays put VP2 nearer (< 0) or farther (> 0);
- the focal length the rays give together (Cauchy fit of their angles, VP1 true) with the
  horizon's roll held at the truth, and with the roll free (and how far that roll is off).

Usage: scripts/rays_on_renders.py SCENE_DIR...   (VPCAL: the binary, default
target/release/vpcal). Needs numpy and scipy.
"""
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.optimize import minimize, minimize_scalar

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def line_diff(a):
    return (a + np.pi / 2) % np.pi - np.pi / 2


def hom(p):
    return np.array([p[0], p[1], 1.0])


def vp2_on_horizon(vp1, roll, pp, f):
    h = np.array([math.cos(roll), math.sin(roll)])
    foot = vp1 + np.dot(pp - vp1, h) * h
    s = (-f * f - np.dot(vp1 - pp, foot - pp)) / np.dot(vp1 - pp, h)
    return foot + s * h


def vehicle_records(folder, vpcal, tmp):
    """The scene's name, its camera.json and the records of `calibrate --vehicles` with its true
    boxes (empty when the run wrote none)."""
    name = os.path.basename(folder.rstrip("/"))
    out = os.path.join(tmp, name + ".veh.json")
    subprocess.run([vpcal, "calibrate", os.path.join(folder, "video.mp4"), "--detections",
                    os.path.join(folder, "detections.csv"), "--quiet", "-o", os.path.join(tmp, name + ".json"),
                    "--vehicles", out], capture_output=True)
    cam = json.load(open(os.path.join(folder, "camera.json")))
    return name, cam, (json.load(open(out)) if os.path.exists(out) else [])


def each_scene(measure):
    """Runs `measure(folder, vpcal, tmp)` on every scene folder of the command line."""
    if len(sys.argv) < 2:
        sys.exit(sys.modules["__main__"].__doc__)
    vpcal = os.environ.get("VPCAL", os.path.join(ROOT, "target", "release", "vpcal"))
    with tempfile.TemporaryDirectory() as tmp:
        for folder in sys.argv[1:]:
            measure(folder, vpcal, tmp)


def scene(folder, vpcal, tmp):
    name, cam, records = vehicle_records(folder, vpcal, tmp)
    v1, v2, pp, f = np.array(cam["vp1"]), np.array(cam["vp2"]), np.array(cam["pp"]), cam["focal_px"]
    horizon = np.cross(hom(v1), hom(v2))
    turns, ln_ratio, centres, angles = [], [], [], []
    for r in records:
        p2 = r.get("vp2")
        if r.get("vps_copied") or p2 is None or None in p2:
            continue
        c = np.array(r["box_center"])
        a2 = math.atan2(p2[1] - c[1], p2[0] - c[0])
        to2 = math.atan2(v2[1] - c[1], v2[0] - c[0])
        to1 = math.atan2(v1[1] - c[1], v1[0] - c[0])
        turns.append(math.degrees(line_diff(a2 - to2)) * np.sign(line_diff(to1 - to2)))
        x = np.cross(np.cross(hom(c), hom(p2)), horizon)
        f2 = -np.dot(v1 - pp, x[:2] / x[2] - pp) if abs(x[2]) > 1e-12 else math.inf
        ln_ratio.append(0.5 * math.log(f2) - math.log(f) if 0 < f2 < math.inf else (5.0 if f2 > 0 else -5.0))
        centres.append(c)
        angles.append(a2)
    if not turns:
        print(f"{name:22s} no records")
        return
    C, A = np.array(centres), np.array(angles)
    roll0 = math.atan2(v2[1] - v1[1], v2[0] - v1[0])

    def cost(ln_f, roll):
        q = vp2_on_horizon(v1, roll, pp, math.exp(ln_f))
        d = line_diff(A - np.arctan2(q[1] - C[:, 1], q[0] - C[:, 0])) / math.radians(1.0)
        return float(np.sum(np.log1p(d * d)))

    w = float(cam["width"])
    grid = np.linspace(math.log(0.3 * w), math.log(15 * w), 200)
    g = grid[int(np.argmin([cost(x, roll0) for x in grid]))]
    held = minimize_scalar(lambda x: cost(x, roll0), bounds=(g - 0.05, g + 0.05), method="bounded").x
    free = minimize(lambda q: cost(q[0], q[1]), [held, roll0], method="Nelder-Mead").x
    print(f"{name:22s} VP2 {abs(v2[0] - pp[0]) / w:5.1f} widths out  records {len(turns):5d}  turn {np.median(turns):+5.2f} deg  "
          f"meets the horizon at f x {math.exp(np.median(ln_ratio)):4.2f}  rays' fit: true roll f x {math.exp(held) / f:5.2f}, "
          f"roll free f x {math.exp(free[0]) / f:5.2f} (roll {math.degrees(free[1] - roll0):+5.2f} deg)")


if __name__ == "__main__":
    each_scene(scene)
