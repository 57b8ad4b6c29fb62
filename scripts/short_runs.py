#!/usr/bin/env python3
"""Short footage against the whole clip (issue 41): calibrate each clip on its first N frames
(N = 20, 45, 100, 300 by default) and on the whole clip (at most --full frames), and print per
short run its status, focal length and 68 % interval, whether that interval holds the whole
clip's focal length, and how far its VP1 and horizon lie from the whole clip's. A short run
should either hold the longer run's estimate in its interval or say it cannot tell
(`not_enough_evidence`, or `unreliable` with the reason), never a narrow wrong answer.

Usage: scripts/short_runs.py OUT CLIP... [--frames 20,45,100,300] [--full 1500]
       (vpcal: $CARGO_TARGET_DIR/release/vpcal or target/release/vpcal)
"""
import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path


def calibrate(vpcal, clip, out, frames):
    out.parent.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(
        [vpcal, "calibrate", str(clip), "-o", str(out), "--quiet", "--max-frames", str(frames)],
        capture_output=True, text=True)
    if not out.exists():
        return None, proc.returncode
    return json.loads(out.read_text()), proc.returncode


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("clips", nargs="+")
    ap.add_argument("--frames", default="20,45,100,300")
    ap.add_argument("--full", type=int, default=1500)
    a = ap.parse_args()
    root = Path(__file__).resolve().parent.parent
    vpcal = Path(os.environ.get("CARGO_TARGET_DIR", root / "target")) / "release" / "vpcal"
    frames = [int(x) for x in a.frames.split(",")]
    held = total = 0
    print(f"{'clip':34s} {'frames':>6s} {'status':19s} {'source':12s} {'f':>6s} "
          f"{'interval':>11s} {'full f':>6s} held {'vp1 off':>8s} {'roll off':>8s}")
    for clip in a.clips:
        name = Path(clip).stem
        full, _ = calibrate(vpcal, clip, Path(a.out) / name / "full.json", a.full)
        if not full or full.get("status") == "not_enough_evidence":
            print(f"{name[:34]:34s} full clip not calibrated: skipped")
            continue
        f_full = full["focal_px"]
        for n in frames:
            d, code = calibrate(vpcal, clip, Path(a.out) / name / f"{n}.json", n)
            if d is None:
                print(f"{name[:34]:34s} {n:6d} exit {code}, no file")
                continue
            st = d["status"]
            if st == "not_enough_evidence":
                print(f"{name[:34]:34s} {n:6d} {st:19s}")
                continue
            lo, hi = d.get("focal_interval_px") or (math.nan, math.nan)
            ok = lo <= f_full <= hi
            if st == "calibrated":
                total += 1
                held += ok
            vp1 = d["vp1"]
            off = math.hypot(vp1[0] - full["vp1"][0], vp1[1] - full["vp1"][1])
            roll = d["roll_deg"] - full["roll_deg"]
            print(f"{name[:34]:34s} {n:6d} {st:19s} {d['focal_source']:12s} {d['focal_px']:6.0f} "
                  f"{lo:5.0f}-{hi:<5.0f} {f_full:6.0f} {'yes' if ok else 'NO ':4s} "
                  f"{off:7.1f}px {roll:+7.2f}°")
    print(f"calibrated short runs whose interval holds the whole clip's focal length: "
          f"{held} of {total}")


if __name__ == "__main__":
    sys.exit(main())
