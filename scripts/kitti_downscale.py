#!/usr/bin/env python3
"""The same real KITTI vehicles at smaller sizes: the whole frames downscaled, then the network.

KITTI's vehicles carry exact vanishing points (`$VPCAL_DATA/real/kitti_object/vp_gt.json`).
For each factor K this writes a copy of that folder under OUT/kK with every frame downscaled
by K (an area filter, as a lower-resolution camera would see the scene) and the truth scaled
with it (principal point, focal length, 2D boxes, the VPs' pixel coordinates), runs
`vpcal eval kitti --all --vehicles` on it, and prints, for the vehicles that are clean at full
size (unoccluded, untruncated, at least 20 px tall), the median direction errors of the
network's VP1 and VP2 and of the edgelets' VP2 at each factor with the median larger box
side. The same vehicles at every size: what changes is only how many pixels they cover.

Usage: scripts/kitti_downscale.py [--model WEIGHTS] VPCAL OUT K [K ...]   (e.g. 1 0.5 0.35 0.25)
(without --model: the model built into VPCAL)
"""
import json
import os
import statistics
import subprocess
import sys

from PIL import Image


def data_dir():
    here = os.path.dirname(os.path.abspath(__file__))
    return os.environ.get("VPCAL_DATA", os.path.join(here, "../../shared/data"))


def downscaled(src, dst, k):
    """Write the folder `src` downscaled by `k` into `dst` (vp_gt.json and image_2/)."""
    os.makedirs(os.path.join(dst, "image_2"), exist_ok=True)
    truth = json.load(open(os.path.join(src, "vp_gt.json")))
    for frame in truth["frames"].values():
        image = Image.open(os.path.join(src, frame["image"]))
        w, h = image.size
        image.resize((round(w * k), round(h * k)), Image.BOX).save(os.path.join(dst, frame["image"]))
        frame["pp"] = [p * k for p in frame["pp"]]
        if frame.get("fx"):
            frame["fx"] *= k
        for v in frame["vehicles"]:
            v["box2d_label"] = [c * k for c in v["box2d_label"]]
            for key in ("vp1_h", "vp2_h"):
                x, y, w_h = v[key]
                v[key] = [x * k, y * k, w_h]
            for stale in ("box2d_proj", "vp1", "vp2"):
                v.pop(stale, None)
    json.dump(truth, open(os.path.join(dst, "vp_gt.json"), "w"))


def median(values):
    values = [v for v in values if v is not None]
    return (statistics.median(values), len(values)) if values else (float("nan"), 0)


def main():
    args = sys.argv[1:]
    model = []
    if args[:1] == ["--model"] and len(args) > 1:
        model, args = ["--model", args[1]], args[2:]
    if len(args) < 3:
        sys.exit(__doc__)
    vpcal, out, factors = args[0], args[1], [float(k) for k in args[2:]]
    src = os.path.join(data_dir(), "real", "kitti_object")
    records = {}
    for k in factors:
        dst = os.path.join(out, f"k{k}")
        downscaled(src, dst, k)
        veh = os.path.join(dst, "vehicles.json")
        r = subprocess.run([vpcal, "eval", "kitti", "--data", dst, "--all", "--vehicles", veh] + model,
                           capture_output=True, text=True)
        if r.returncode:
            sys.exit(f"vpcal eval kitti failed at K={k}: {r.stderr.strip()}")
        records[k] = {(v["frame"], v["index"]): v for v in json.load(open(veh))}
    # The vehicles clean at the largest size, followed through every factor.
    first = records[max(factors)]
    clean = [key for key, v in first.items() if v["clean"]]
    print(f"{len(clean)} vehicles clean at K={max(factors)}; median degrees (count):")
    print(f"{'K':>5} {'box side px':>11} {'network VP1':>14} {'network VP2':>14} {'edgelet VP2':>14}")
    for k in sorted(factors, reverse=True):
        vs = [records[k][key] for key in clean]
        side = statistics.median(max(v["bbox"][2] - v["bbox"][0], v["bbox"][3] - v["bbox"][1]) for v in vs)
        cells = [median([v[f] for v in vs]) for f in ("network_vp1_deg", "network_vp2_deg", "edgelet_vp2_deg")]
        print(f"{k:5.2f} {side:11.0f} " + " ".join(f"{m:8.2f} ({n:2d})" for m, n in cells))


if __name__ == "__main__":
    main()
