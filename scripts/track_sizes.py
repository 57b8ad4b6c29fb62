#!/usr/bin/env python3
"""Per-vehicle lane (and size, where the tracks have one) of `vpcal calibrate --tracks` against a
synthetic scene's truth.

usage: scripts/track_sizes.py SCENE_DIR [SCENE_DIR ...] [--vpcal BIN] [--detections true|motion|yolox]
       [--scale taped|auto] [--out DIR]

SCENE_DIR is a `vpcal synth scene/suite` dataset folder (video.mp4, detections.csv, vehicles.jsonl,
gt_data.json). Each track is matched to the true vehicle its boxes overlap most (IoU >= 0.5 in most
of its boxes); prints per scene the median relative error of length, width and height and the lane
agreement (pairs of matched tracks: same true lane <=> same found lane), and pooled numbers.
"""
import argparse, json, os, subprocess, sys, statistics as st
from collections import Counter, defaultdict


def iou(a, b):
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[2], b[2]), min(a[3], b[3])
    i = max(0, x1 - x0) * max(0, y1 - y0)
    u = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - i
    return i / u if u > 0 else 0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--vpcal", default="target/release/vpcal")
    ap.add_argument("--detections", default="true")
    ap.add_argument("--scale", default="taped")
    ap.add_argument("--out", default="/tmp/track_sizes")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    pooled = defaultdict(list)
    for d in a.scenes:
        name = os.path.basename(os.path.normpath(d))
        gt = json.load(open(os.path.join(d, "gt_data.json")))
        cmd = [a.vpcal, "calibrate", os.path.join(d, "video.mp4"), "--quiet",
               "-o", f"{a.out}/{name}.calib.json", "--tracks", f"{a.out}/{name}.tracks.json"]
        if a.detections == "true":
            cmd += ["--detections", os.path.join(d, "detections.csv")]
        else:
            cmd += ["--detector", a.detections]
        if a.scale == "taped":
            m = gt["distanceMeasurement"][0]
            cmd += ["--scale-points", ",".join(f"{v:.3f}" for v in m["p1"][:2] + m["p2"][:2]),
                    "--scale-distance", str(m["distance"])]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            print(name, "calibrate failed:", r.stderr.strip().splitlines()[-1:])
            continue
        truth = defaultdict(list)  # frame -> [(id, box, dims)]
        dims = {}
        for line in open(os.path.join(d, "vehicles.jsonl")):
            v = json.loads(line)
            if v.get("parked"):
                continue
            truth[v["frame"]].append((v["id"], v["box_clipped"]))
            dims[v["id"]] = v["dims_m"]
        lane_of = {c["carId"]: c["laneIndex"][0] for c in gt["cars"] if c.get("laneIndex")}
        tracks = json.load(open(f"{a.out}/{name}.tracks.json"))["tracks"]
        errs = defaultdict(list)
        matched = []
        for t in tracks:
            votes = Counter()
            n = len(t["frames"])
            for k in range(n):
                # Tracks keep contact points (box bottom centres): the true vehicle whose
                # box's bottom edge is nearest.
                f, x, y = t["frames"][k], t["x_px"][k], t["y_px"][k]
                best = None
                for vid, b in truth.get(f, []):
                    if b[0] <= x <= b[2] and abs(b[3] - y) <= 0.15 * (b[3] - b[1]):
                        dist = abs(b[3] - y) + abs(0.5 * (b[0] + b[2]) - x)
                        if best is None or dist < best[0]:
                            best = (dist, vid)
                if best:
                    votes[best[1]] += 1
            if not votes:
                continue
            vid, c = votes.most_common(1)[0]
            if c < 0.5 * n:
                continue
            if t.get("length_m") is not None:
                tl, tw, th = dims[vid]
                errs["length"].append(t["length_m"] / tl - 1)
                errs["width"].append(t["width_m"] / tw - 1)
                errs["height"].append(t["height_m"] / th - 1)
            if vid in lane_of and t.get("lane") is not None:
                matched.append((lane_of[vid], t["lane"], t["direction"]))
        agree = total = 0
        for i in range(len(matched)):
            for j in range(i + 1, len(matched)):
                total += 1
                agree += (matched[i][0] == matched[j][0]) == (matched[i][1] == matched[j][1])
        def med(v):
            return f"{100 * st.median(v):+.1f}%" if v else "-"
        def mabs(v):
            return f"{100 * st.median([abs(x) for x in v]):.1f}%" if v else "-"
        lanes_true = len({m[0] for m in matched})
        lanes_found = len({m[1] for m in matched})
        print(f"{name}: {len(tracks)} tracks, {len(matched)} matched with a lane, {len(errs['length'])} sized; "
              f"length median {med(errs['length'])} (|.| {mabs(errs['length'])}), "
              f"width {med(errs['width'])}, height {med(errs['height'])} (|.| {mabs(errs['height'])}); "
              f"lanes true {lanes_true} found {lanes_found}, pair agreement "
              f"{agree}/{total}" + (f" ({100 * agree / total:.0f}%)" if total else ""))
        for k, v in errs.items():
            pooled[k] += v
        pooled["agree"].append(agree)
        pooled["pairs"].append(total)
    if pooled["length"]:
        print(f"pooled sizes: {len(pooled['length'])} vehicles; |length error| median "
              f"{100 * st.median([abs(x) for x in pooled['length']]):.1f}%, length bias "
              f"{100 * st.median(pooled['length']):+.1f}%, |height| "
              f"{100 * st.median([abs(x) for x in pooled['height']]):.1f}%")
    print(f"pooled lanes: pairs agreeing {sum(pooled['agree'])}/{sum(pooled['pairs'])}")


if __name__ == "__main__":
    main()
