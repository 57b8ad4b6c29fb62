#!/usr/bin/env python3
"""Compare two builds' aggregation on the same per-vehicle records.

`record` runs `vpcal calibrate` once (with the binary given) on the synthetic suite (true
boxes, as scripts/suite_focal.sh) and on the real clips (traffic_video and the corpus,
--max-frames 300), keeping each run's `--vehicles` and `--scene-edgelets` files in DIR.
`compare` runs `vpcal aggregate` on those records with two binaries and prints per input the
focal source, focal length, 68 % interval and (suite) the error against the true focal length
and whether the interval holds it, then the second binary's focal cues
(`evidence.focal_cues`: source, own focal length, share; X = not used).

The detector and network run once; the aggregation, which is what changes, runs twice.

Usage:
  scripts/reaggregate.py record DIR --vpcal BIN [--suite SUITE_DIR]
  scripts/reaggregate.py compare DIR BIN_A BIN_B [NAME...]
"""
import argparse
import glob
import json
import math
import os
import subprocess
import sys


def data_dir():
    return os.environ.get("VPCAL_DATA", os.path.join(os.path.dirname(__file__), "../../shared/data"))


def record(a):
    os.makedirs(a.dir, exist_ok=True)
    jobs = []
    if a.suite:
        for d in sorted(glob.glob(os.path.join(a.suite, "dataset", "*/"))):
            n = os.path.basename(d.rstrip("/"))
            jobs.append((n, [os.path.join(d, "video.mp4"), "--detections", os.path.join(d, "detections.csv")],
                         os.path.join(d, "camera.json")))
    data = data_dir()
    clips = sorted(glob.glob(os.path.join(data, "traffic_video", "*.avi")) +
                   glob.glob(os.path.join(data, "traffic_video", "*.mp4")) +
                   glob.glob(os.path.join(data, "traffic_corpus", "clips", "*")))
    for c in clips:
        jobs.append((os.path.splitext(os.path.basename(c))[0], [c, "--max-frames", "300"], None))
    for i, (n, args, truth) in enumerate(jobs):
        out = os.path.join(a.dir, n)
        if os.path.exists(out + ".veh.json"):
            continue
        print(f"[{i + 1}/{len(jobs)}] {n}", file=sys.stderr)
        subprocess.run([a.vpcal, "calibrate", *args, "--quiet", "-o", out + ".calib.json",
                        "--vehicles", out + ".veh.json", "--scene-edgelets", out + ".scene.json"],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        if truth:
            with open(out + ".truth.json", "w") as f:
                json.dump({"focal_px": json.load(open(truth))["focal_px"]}, f)


def aggregate(binary, base, tag):
    calib = base + ".calib.json"
    out = f"{base}.{tag}.json"
    args = [binary, "aggregate", base + ".veh.json", "--scene-edgelets", base + ".scene.json", "-o", out]
    try:
        size = json.load(open(calib)).get("image_size")
        if size:
            args += ["--image-size", "%dx%d" % tuple(size)]
    except (OSError, ValueError):
        pass
    r = subprocess.run(args, capture_output=True, text=True)
    try:
        return json.load(open(out))
    except (OSError, ValueError):
        return {"status": f"exit {r.returncode}"}


def row(d, truth):
    if d.get("status") not in ("calibrated", "rough", "unreliable"):
        return "%-44s" % d.get("status", "?")[:20]
    f = d["focal_px"]
    lo, hi = d.get("focal_interval_px") or [math.nan, math.nan]
    err = "" if truth is None else "%+6.1f%% %s" % (100 * (f / truth - 1), "in " if lo <= truth <= hi else "OUT")
    return "%-12s %6.0f [%5.0f-%6.0f] %s" % (d["focal_source"][:12], f, lo, hi, err)


def compare(a):
    names = a.names or sorted(os.path.basename(p)[:-len(".veh.json")]
                              for p in glob.glob(os.path.join(a.dir, "*.veh.json")))
    for n in names:
        base = os.path.join(a.dir, n)
        truth = None
        if os.path.exists(base + ".truth.json"):
            truth = json.load(open(base + ".truth.json"))["focal_px"]
        x, y = aggregate(a.bin_a, base, "a"), aggregate(a.bin_b, base, "b")
        cues = " ".join("%s:%.0f/%.2f%s" % (c["source"], c["focal_px"], c["share"], "" if c["used"] else "X")
                        for c in (y.get("evidence") or {}).get("focal_cues", []))
        print("%-36s %-6s | %s | %s | %s" % (n[:36], "" if truth is None else "%.0f" % truth,
                                             row(x, truth), row(y, truth), cues))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("dir")
    r.add_argument("--vpcal", default="target/release/vpcal")
    r.add_argument("--suite", help="the synthetic suite's folder (vpcal synth suite -o DIR --frames 100)")
    c = sub.add_parser("compare")
    c.add_argument("dir")
    c.add_argument("bin_a")
    c.add_argument("bin_b")
    c.add_argument("names", nargs="*")
    a = ap.parse_args()
    record(a) if a.cmd == "record" else compare(a)


if __name__ == "__main__":
    main()
