#!/usr/bin/env python3
"""How far the edges across rendered vehicles turn towards VP1, per scene.

For each synthetic scene under SCENE_ROOT/dataset/<scene>/ (rendered by `vpcal synth scene`
or `synth suite`, with camera.json and detections.csv), runs `vpcal calibrate` with the true
boxes and `--vehicles` (kept in OUT_DIR), then takes each box's edgelets that the edgelet fit
would use against the true VPs (within 12 degrees of the direction to VP2, farther than 4
from the direction to VP1) and fits one turn per vehicle box: the angle that minimises the
Cauchy loss (scale 1 degree) of the edgelets' angles less the true directions to VP2, signed
towards the direction to VP1 positive. Prints the median per scene and over all scenes, each
also by the angle between the directions to VP1 and VP2 at the box's centre (the edge filter
mixes the two directions more the closer they are): the measurement behind
`vpcal_geom::aggregate::edgelets::EDGE_TURN_DEG` and `edge_turn_share`.

Usage: scripts/edge_turn.py VPCAL SCENE_ROOT OUT_DIR [SCENE...]
"""
import glob
import json
import math
import os
import subprocess
import sys

GATE_VP2_DEG = 12.0
EXCLUDE_VP1_DEG = 4.0
SCALE_DEG = 1.0


def line_diff(a):
    """An angle between two lines folded into [-pi/2, pi/2)."""
    return (a + math.pi / 2) % math.pi - math.pi / 2


def box_turn(edgelets, vp1, vp2):
    """One box's turn towards VP1 (degrees), or None with fewer than 3 edgelets."""
    r = []
    for x, y, a, _ in edgelets:
        d2 = math.atan2(vp2[1] - y, vp2[0] - x)
        d1 = math.atan2(vp1[1] - y, vp1[0] - x)
        res = line_diff(a - d2)
        if abs(res) < math.radians(GATE_VP2_DEG) and abs(line_diff(a - d1)) > math.radians(EXCLUDE_VP1_DEG):
            r.append(math.degrees(res) * math.copysign(1.0, line_diff(d1 - d2)))
    if len(r) < 3:
        return None
    grid = [-6.0 + 0.02 * i for i in range(601)]
    cost = [sum(math.log1p(((v - g) / SCALE_DEG) ** 2) for v in r) for g in grid]
    return grid[cost.index(min(cost))]


ALPHA_BINS = [(0, 15), (15, 30), (30, 40), (40, 60), (60, 90)]


def box_alpha(centre, vp1, vp2):
    """The angle between the directions from `centre` to the two VPs, degrees in [0, 90]."""
    x, y = centre
    d1 = math.atan2(vp1[1] - y, vp1[0] - x)
    d2 = math.atan2(vp2[1] - y, vp2[0] - x)
    return abs(math.degrees(line_diff(d1 - d2)))


def by_alpha(rows):
    """'alpha lo-hi: median (n)' for each bin of ALPHA_BINS with boxes."""
    out = []
    for lo, hi in ALPHA_BINS:
        t = [turn for turn, a in rows if lo <= a < hi]
        if t:
            out.append(f"{lo}-{hi}: {median(t):+.2f} ({len(t)})")
    return "  ".join(out)


def median(v):
    v = sorted(v)
    n = len(v)
    return float("nan") if n == 0 else (v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2]))


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    vpcal, root, out = sys.argv[1:4]
    only = set(sys.argv[4:])
    os.makedirs(out, exist_ok=True)
    everything = []
    for d in sorted(glob.glob(os.path.join(root, "dataset", "*/"))):
        scene = os.path.basename(d.rstrip("/"))
        if only and scene not in only:
            continue
        veh = os.path.join(out, scene + ".veh.json")
        if not os.path.exists(veh):
            r = subprocess.run([vpcal, "calibrate", os.path.join(d, "video.mp4"), "--detections",
                                os.path.join(d, "detections.csv"), "--vehicles", veh,
                                "-o", os.path.join(out, scene + ".calib.json")],
                               capture_output=True, text=True)
            if r.returncode:
                print(f"{scene}: calibrate failed: {r.stderr.strip()[:200]}")
                continue
        cam = json.load(open(os.path.join(d, "camera.json")))
        rows = [(t, box_alpha(it["box_center"], cam["vp1"], cam["vp2"]))
                for it in json.load(open(veh))
                if (t := box_turn(it.get("edgelets") or [], cam["vp1"], cam["vp2"])) is not None]
        everything += rows
        turns = [t for t, _ in rows]
        print(f"{scene:24s} boxes {len(turns):5d}  median turn towards VP1 {median(turns):+.2f} deg")
        print(f"{'':24s} by angle between the VPs' directions (deg): {by_alpha(rows)}")
    turns = [t for t, _ in everything]
    print(f"{'all':24s} boxes {len(turns):5d}  median turn towards VP1 {median(turns):+.2f} deg")
    print(f"{'':24s} by angle between the VPs' directions (deg): {by_alpha(everything)}")


if __name__ == "__main__":
    main()
