#!/usr/bin/env python3
"""The focal length from one known distance along the road and one across it, per scene.

For each calibration CALIB_DIR/<scene>[.<tag>].calib.json of a synthetic scene (rendered by
`vpcal synth scene` or `synth suite` under SCENE_ROOT/dataset/<scene>/), runs `vpcal scale`
with the scene's first along-the-road and first across-the-road distance of gt_data.json
(exact, from the renderer) and prints the focal length before (the footage's), from the two
lengths alone, and after (the two combined), against camera.json's, with the 68 % interval.

Usage: scripts/distance_focal.py VPCAL SCENE_ROOT CALIB_DIR
"""
import glob
import json
import os
import subprocess
import sys


def main():
    vpcal, root, calibs = sys.argv[1:4]
    out = os.path.join(calibs, "distance_focal.out.json")
    for c in sorted(glob.glob(os.path.join(calibs, "*.calib.json"))):
        parts = os.path.basename(c).split(".")
        scene, tag = parts[0], (parts[1] if len(parts) > 3 else "")
        d = os.path.join(root, "dataset", scene)
        k = json.load(open(c))
        if k["status"] == "not_enough_evidence":
            print(f"{scene:22s} {tag:7s} not calibrated")
            continue
        truth = json.load(open(os.path.join(d, "camera.json")))["focal_px"]
        ms = json.load(open(os.path.join(d, "gt_data.json")))["distanceMeasurement"]
        along = next(m for m in ms if m["toVP1"])
        across = next(m for m in ms if not m["toVP1"])
        args = []
        for m in (along, across):
            pts = ",".join("%.2f" % v for v in m["p1"][:2] + m["p2"][:2])
            args += ["--points", pts, "--distance", str(m["distance"])]
        r = subprocess.run([vpcal, "scale", c, "-o", out, "--json"] + args,
                           capture_output=True, text=True)
        if r.returncode:
            print(f"{scene:22s} {tag:7s} failed: {r.stderr.strip()[:160]}")
            continue
        fo = json.loads(r.stdout)["focal"]
        f, (lo, hi) = fo["focal_px"], fo["focal_interval_px"]
        lengths = (fo["from_lengths"] or {}).get("focal_px", float("nan"))
        print(f"{scene:22s} {tag:7s} true {truth:6.0f}  footage {fo['previous_focal_px']:6.0f} "
              f"({fo['previous_focal_source']:12s})  lengths {lengths:6.0f} {100 * (lengths / truth - 1):+6.1f}%  "
              f"-> {f:6.0f} {100 * (f / truth - 1):+6.1f}% [{lo:.0f}-{hi:.0f}] "
              f"holds={lo <= truth <= hi} {fo['focal_source']}")


if __name__ == "__main__":
    main()
