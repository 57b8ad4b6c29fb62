#!/usr/bin/env python3
"""The horizon's roll from the vehicles' edgelets on rendered scenes with known cameras.

For each scene folder (`vpcal synth scene` / `vpcal synth suite` output), runs `vpcal
calibrate --detections detections.csv --vehicles` and fits the roll alone (VP1 and f at the
truth, a Cauchy loss of 1 degree on the edgelets' angles to VP2, as the edgelet fit does) to the
edgelets of every record within 12 degrees of (a) the network's VP2 ray of the record, as the
calibration gates them, and (b) the true VP2's direction; edgelets within 4 degrees of the
direction to VP1 left out, at most 20 a record, strongest first. Prints both rolls against
the true horizon's angle: whether the edgelets themselves, or the network's gate, turn it.
Third, (c) the true-VP2 gate keeping only edgelets at least 10 px from every recorded edgelet
that points at VP1 (the car's edges along it): whether corners turn them.

Usage: scripts/edgelet_roll_on_renders.py SCENE_DIR...   (VPCAL: the binary, default
target/release/vpcal). Needs numpy and scipy.
"""
import math
import os
import sys

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.spatial import cKDTree

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rays_on_renders import each_scene, line_diff, vehicle_records, vp2_on_horizon  # noqa: E402


def scene(folder, vpcal, tmp):
    name, cam, records = vehicle_records(folder, vpcal, tmp)
    if not records:
        print(f"{name:22s} no records")
        return
    v1, v2, pp, f = np.array(cam["vp1"]), np.array(cam["vp2"]), np.array(cam["pp"]), cam["focal_px"]
    roll0 = math.atan2(v2[1] - v1[1], v2[0] - v1[0])

    def gated(towards, clear_px=0.0):
        points, angles = [], []
        for r in records:
            c = np.array(r["box_center"])
            q = towards(r)
            if q is None:
                continue
            a2 = math.atan2(q[1] - c[1], q[0] - c[0])
            along = [e[:2] for e in r.get("edgelets", [])
                     if abs(line_diff(e[2] - math.atan2(v1[1] - e[1], v1[0] - e[0]))) <= math.radians(4)]
            tree = cKDTree(np.array(along)) if along and clear_px > 0 else None
            kept = [e for e in r.get("edgelets", [])
                    if abs(line_diff(e[2] - a2)) < math.radians(12)
                    and abs(line_diff(e[2] - math.atan2(v1[1] - e[1], v1[0] - e[0]))) > math.radians(4)
                    and (tree is None or tree.query(e[:2])[0] >= clear_px)]
            for e in sorted(kept, key=lambda e: -e[3])[:20]:
                points.append(e[:2])
                angles.append(e[2])
        return np.array(points), np.array(angles)

    def roll_fit(points, angles):
        def cost(roll):
            q = vp2_on_horizon(v1, roll, pp, f)
            d = line_diff(angles - np.arctan2(q[1] - points[:, 1], q[0] - points[:, 0])) / math.radians(1.0)
            return float(np.sum(np.log1p(d * d)))
        return minimize_scalar(cost, bounds=(roll0 - math.radians(5), roll0 + math.radians(5)), method="bounded").x

    def network(r):
        q = r.get("vp2")
        return None if r.get("vps_copied") or q is None or None in q else np.array(q)

    pn, an = gated(network)
    pt, at = gated(lambda r: v2)
    pc, ac = gated(lambda r: v2, 10.0)
    print(f"{name:22s} roll (f and VP1 true) from edgelets gated by the network's rays {math.degrees(roll_fit(pn, an) - roll0):+5.2f} deg "
          f"({len(an)}), by the true VP2 {math.degrees(roll_fit(pt, at) - roll0):+5.2f} deg ({len(at)}), "
          f"away from corners {math.degrees(roll_fit(pc, ac) - roll0):+5.2f} deg ({len(ac)}) off the truth")


if __name__ == "__main__":
    each_scene(scene)
