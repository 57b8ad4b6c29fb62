#!/usr/bin/env python3
"""Which part of an estimated camera makes the speed error of synthetic scenes: replace VP1,
the horizon's roll or the focal length of vpcal's camera by the scene's true one, refit the
scale to the scene's first taped distance, and write each variant as a system file next to
vpcal's.

Usage: scripts/speed_camera_swap.py OUT
  OUT  a `scripts/speed_e2e.sh OUT DETECTOR taped SCENES...` folder (dataset/<scene>/ with
       camera.json and gt_data.json, results/<scene>/system_vpcal.json)

Writes results/<scene>/system_{truecam,trueVP1,trueF,trueRoll}.json (vpcal's tracks; the true
camera; the true VP1 with vpcal's roll and focal length; vpcal's VP1 and roll with the true
focal length; vpcal's VP1 and focal length with the true roll) and prints vpcal's and the true
focal length, roll and VP1 per scene. Then, per variant:
  vpcal eval speed --dataset OUT/dataset --results OUT/results --image-size WxH --system NAME
The road plane is BrnoCompSpeed's, from `scripts/bcs_ratio_errors.py`. Needs numpy.
"""
import json
import math
import os
import sys

import numpy as np

from bcs_ratio_errors import camera, road_point


def vps_for(vp1, roll_deg, f, pp):
    """VP1 and the VP2 on the horizon through VP1 at `roll_deg` that is orthogonal for `f`."""
    vp1, pp = np.asarray(vp1, float), np.asarray(pp, float)
    u = np.array([math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))])
    a = vp1 - pp
    t = -(np.dot(a, a) + f * f) / np.dot(u, a)
    return vp1.tolist(), (vp1 + t * u).tolist()


def horizon_deg(vp1, vp2):
    d = np.asarray(vp2, float) - np.asarray(vp1, float)
    if d[0] < 0:
        d = -d
    return math.degrees(math.atan2(d[1], d[0]))


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    for name in sorted(os.listdir(os.path.join(out, "results"))):
        scene = os.path.join(out, "dataset", name)
        gt = json.load(open(os.path.join(scene, "gt_data.json")))
        truth = json.load(open(os.path.join(scene, "camera.json")))
        system = json.load(open(os.path.join(out, "results", name, "system_vpcal.json")))
        est = system["camera_calibration"]
        pp = est["pp"]
        f_est = camera(est["vp1"], est["vp2"], pp)[0]
        f_true = camera(truth["vp1"], truth["vp2"], pp)[0]
        roll_est, roll_true = horizon_deg(est["vp1"], est["vp2"]), horizon_deg(truth["vp1"], truth["vp2"])
        variants = {
            "truecam": (truth["vp1"], truth["vp2"]),
            "trueVP1": vps_for(truth["vp1"], roll_est, f_est, pp),
            "trueF": vps_for(est["vp1"], roll_est, f_true, pp),
            "trueRoll": vps_for(est["vp1"], roll_true, f_est, pp),
        }
        taped = gt["distanceMeasurement"][0]
        for variant, (vp1, vp2) in variants.items():
            focal, normal = camera(vp1, vp2, pp)
            ends = [road_point(taped[k], pp, focal, normal) for k in ("p1", "p2")]
            units = np.linalg.norm(ends[0] - ends[1])
            calib = {"pp": pp, "scale": taped["distance"] / units,
                     "vp1": [float(v) for v in vp1], "vp2": [float(v) for v in vp2]}
            with open(os.path.join(out, "results", name, f"system_{variant}.json"), "w") as fh:
                json.dump({"cars": system["cars"], "camera_calibration": calib}, fh)
        print(f"{name}: focal {f_est:.0f} (true {f_true:.0f}) px, roll {roll_est:.2f} "
              f"(true {roll_true:.2f})°, VP1 ({est['vp1'][0]:.1f}, {est['vp1'][1]:.1f}) "
              f"(true ({truth['vp1'][0]:.1f}, {truth['vp1'][1]:.1f}))")


if __name__ == "__main__":
    main()
