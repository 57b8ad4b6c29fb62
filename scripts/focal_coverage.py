#!/usr/bin/env python3
"""Coverage of the focal interval on real data: BrnoCompSpeed sessions 0-3, the three public
CNNs' per-vehicle VPs (VPCAL_DATA/bcs/vp_outputs), against the reference cameras fitted to
each video's taped distances (VPCAL_DATA/bcs/camera_truth.json).

For every VPout file it runs `vpcal aggregate --pp bcs --json` (robust method, 30 bootstrap
resamples) and prints the focal length, its source, its 68 % interval, whether the interval
contains the reference focal length, and the pooled coverage and median interval width (as
a fraction of the focal length), overall and per source.

Usage: python3 scripts/focal_coverage.py [--vpcal target/release/vpcal] [--method robust]
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
from concurrent.futures import ThreadPoolExecutor


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vpcal", default="target/release/vpcal")
    ap.add_argument("--method", default="robust")
    a = ap.parse_args()
    data = os.environ.get("VPCAL_DATA", os.path.join(os.path.dirname(__file__), "../../shared/data"))
    truth = json.load(open(os.path.join(data, "bcs/camera_truth.json")))["cameras"]
    jobs = []
    for video in sorted(truth):
        for f in sorted(glob.glob(os.path.join(data, "bcs/vp_outputs", video, "VPout_*.json"))):
            jobs.append((video, f))

    def run(job):
        video, f = job
        r = subprocess.run([a.vpcal, "aggregate", f, "--pp", "bcs", "--json", "--method", a.method],
                           capture_output=True, text=True)
        doc = json.loads(r.stdout) if r.stdout.strip() else {}
        return video, os.path.basename(f), doc

    with ThreadPoolExecutor(max_workers=2) as ex:
        results = list(ex.map(run, jobs))
    rows = []
    for video, name, doc in results:
        ft = truth[video]["focal_px"]
        cnn = name.split("_")[6] + "_" + name.split("_")[7]
        if doc.get("status") != "calibrated":
            print(f"{video:16} {cnn:22} not calibrated")
            rows.append(None)
            continue
        f = doc["focal_px"]
        lo, hi = doc.get("focal_interval_px") or (f, f)
        inside = lo <= ft <= hi
        rows.append((doc.get("focal_source"), inside, (hi - lo) / f, abs(f / ft - 1)))
        print(f"{video:16} {cnn:22} f {f:7.0f} (truth {ft:5.0f}, {100 * (f / ft - 1):+5.1f} %) "
              f"{doc.get('focal_source'):9} 68% {lo:6.0f}-{hi:6.0f} {'IN ' if inside else 'out'}")
    ok = [r for r in rows if r]
    print()
    for src in sorted({r[0] for r in ok}) + [None]:
        sel = [r for r in ok if src is None or r[0] == src]
        if not sel:
            continue
        print(f"{src or 'all':10} {len(sel):3} calibrations: coverage {sum(r[1] for r in sel)}/{len(sel)} "
              f"({100 * sum(r[1] for r in sel) / len(sel):.0f} %), median width "
              f"{100 * statistics.median(r[2] for r in sel):.0f} % of f, median |focal error| "
              f"{100 * statistics.median(r[3] for r in sel):.1f} %")
    print(f"not calibrated: {len(rows) - len(ok)}")


if __name__ == "__main__":
    main()
