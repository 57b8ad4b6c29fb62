#!/usr/bin/env python3
"""The VP network's VP1 rays on real clips, against the VP1 of the clip's straight vehicle tracks.

For every clip, `vpcal calibrate` runs once per model with the same detector and frames and
writes its per-vehicle records (`--vehicles`). The reference VP1 is the one the clip's
straight tracks give (the calibration of the first model, when its `evidence.vp1_from_tracks`
is true; the tracks come from the detector's boxes, not from the network). Each record's
error is the angle, at its box centre, between the line to its predicted VP1 and the line to
the reference VP1 (lines, so at most 90°). Printed per clip and model: the median and the
90th percentile over the records, and their count; with `--split-px S`, also the medians of the
records whose box's larger side (twice the larger of the record's `box_scale`, which holds half
the box's width and height) is under S pixels and of the others (most rays on
far cameras come from small vehicles, where the network sees little).

Usage:
  scripts/real_ray_scatter.py --vpcal target/release/vpcal --out OUT \
      --model bundled --model run/model.safetensors [--every 2] [--max-frames 300] \
      [--split-px 90] CLIP...

`--model bundled` is the model built into the binary. Clips whose tracks do not give VP1
are reported as such (no reference).
"""
import argparse
import json
import math
import os
import subprocess
import sys


def angle_deg(at, a, b):
    ux, uy = a[0] - at[0], a[1] - at[1]
    vx, vy = b[0] - at[0], b[1] - at[1]
    ang = abs(math.degrees(math.atan2(ux * vy - uy * vx, ux * vx + uy * vy)))
    return min(ang, 180.0 - ang)


def percentile(values, q):
    v = sorted(values)
    if not v:
        return float("nan")
    k = (len(v) - 1) * q
    lo, hi = math.floor(k), math.ceil(k)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


def run(vpcal, clip, model, out, every, max_frames):
    os.makedirs(out, exist_ok=True)
    cmd = [vpcal, "calibrate", clip, "--quiet", "-o", f"{out}/calib.json",
           "--vehicles", f"{out}/vehicles.json", "--every", str(every)]
    if max_frames:
        cmd += ["--max-frames", str(max_frames)]
    if model != "bundled":
        cmd += ["--model", model]
    with open(f"{out}/stderr.txt", "w") as err:
        code = subprocess.call(cmd, stdout=subprocess.DEVNULL, stderr=err)
    calib = None
    if os.path.exists(f"{out}/calib.json"):
        with open(f"{out}/calib.json") as f:
            calib = json.load(f)
    items = []
    if os.path.exists(f"{out}/vehicles.json"):
        with open(f"{out}/vehicles.json") as f:
            items = json.load(f)
    return code, calib, items


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--vpcal", default="target/release/vpcal")
    ap.add_argument("--out", required=True)
    ap.add_argument("--model", action="append", required=True)
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--max-frames", type=int, default=0)
    ap.add_argument("--json", help="also write the table here")
    ap.add_argument("--split-px", type=float, default=0.0,
                    help="also the medians below and from this box size (larger side, pixels)")
    ap.add_argument("clips", nargs="+")
    a = ap.parse_args()
    rows = []
    print(f"{'clip':<44} {'model':<28} {'exit':>4} {'n':>6} {'median':>7} {'p90':>7}  reference")
    for clip in a.clips:
        name = os.path.basename(clip.rstrip("/"))
        ref = None
        for mi, model in enumerate(a.model):
            out = os.path.join(a.out, name, f"model{mi}")
            code, calib, items = run(a.vpcal, clip, model, out, a.every, a.max_frames)
            if mi == 0:
                ev = (calib or {}).get("evidence", {})
                if calib and calib.get("vp1") and ev.get("vp1_from_tracks"):
                    ref = calib["vp1"]
            errs, small, large = [], [], []
            if ref is not None:
                for it in items:
                    vp1, at = it.get("vp1"), it.get("box_center")
                    if vp1 is None or at is None or any(v is None for v in vp1 + at):
                        continue
                    e = angle_deg(at, vp1, ref)
                    errs.append(e)
                    size = 2.0 * max(it.get("box_scale") or [0.0])
                    (small if size < a.split_px else large).append(e)
            med, p90 = percentile(errs, 0.5), percentile(errs, 0.9)
            label = os.path.basename(os.path.dirname(model)) + "/" + os.path.basename(model) if model != "bundled" else "bundled"
            print(f"{name:<44} {label[-28:]:<28} {code:>4} {len(errs):>6} {med:>7.2f} {p90:>7.2f}  "
                  f"{'tracks' if ref is not None else 'none (VP1 not from tracks)'}")
            if a.split_px > 0 and errs:
                print(f"{'':<44} {'':<28} {'':>4} {'':>6}  < {a.split_px:g} px: "
                      f"{percentile(small, 0.5):.2f} ({len(small)}), from it: "
                      f"{percentile(large, 0.5):.2f} ({len(large)})")
            rows.append({"clip": name, "model": model, "exit": code, "records": len(errs),
                         "median_deg": med if errs else None, "p90_deg": p90 if errs else None,
                         "reference_vp1": ref,
                         "small_median_deg": percentile(small, 0.5) if small else None,
                         "small_records": len(small),
                         "large_median_deg": percentile(large, 0.5) if large else None,
                         "large_records": len(large)})
            sys.stdout.flush()
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
