#!/usr/bin/env python3
"""How far the edgelets `vpcal calibrate` finds lean away from the true VP directions of a
synthetic scene (for the staircase bias of point-sampled frames; MODEL.md).

Usage: scripts/edgelet_bias.py SCENE_DIR VEHICLES_JSON
  SCENE_DIR      a `vpcal synth scene|suite` scene (dataset/<name>/ with camera.json)
  VEHICLES_JSON  `vpcal calibrate SCENE_DIR/video.mp4 --detections SCENE_DIR/detections.csv
                 --vehicles VEHICLES_JSON` (its items carry the boxes' edgelets)

Prints, for the edgelets within 4° of the true direction to VP2 (and to VP1) at their
position, the median signed angle between edgelet and that direction, and the median true
direction (a bias towards 0° has the opposite sign of the latter). Needs only the standard
library.
"""
import json
import math
import statistics
import sys


def line_diff(a):
    return (a + math.pi / 2) % math.pi - math.pi / 2


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    scene, vehicles = sys.argv[1], sys.argv[2]
    cam = json.load(open(f"{scene}/camera.json"))
    vp1, vp2 = cam["vp1"], cam["vp2"]
    r1, r2, a2 = [], [], []
    for item in json.load(open(vehicles)):
        for x, y, angle, _strength in item.get("edgelets") or []:
            t2 = math.atan2(vp2[1] - y, vp2[0] - x)
            t1 = math.atan2(vp1[1] - y, vp1[0] - x)
            d2, d1 = line_diff(angle - t2), line_diff(angle - t1)
            if abs(d2) < math.radians(4):
                r2.append(math.degrees(d2))
                a2.append(math.degrees(line_diff(t2)))
            if abs(d1) < math.radians(4):
                r1.append(math.degrees(d1))
    if not r2:
        sys.exit(f"{vehicles}: no edgelets near the true VP2 directions")
    print(
        f"{scene}: roll {cam['roll_deg']:+.1f}°; {len(r2)} edgelets towards VP2: median "
        f"{statistics.median(r2):+.3f}° from the truth (true direction median "
        f"{statistics.median(a2):+.2f}°); {len(r1)} towards VP1: median "
        f"{statistics.median(r1) if r1 else float('nan'):+.3f}°"
    )


if __name__ == "__main__":
    main()
