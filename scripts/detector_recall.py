#!/usr/bin/env python3
"""Recall and precision of a detector's boxes against true boxes.

    python3 scripts/detector_recall.py TRUTH.csv DETECTIONS.csv [--min-height 24] [--iou 0.5]

Both files are vpcal detections CSV (frame,x0,y0,x1,y1,score): TRUTH is e.g. a synthetic
scene's detections.csv (true boxes of vehicles at least 30 % visible), DETECTIONS what
`vpcal detect` wrote. Only frames present in DETECTIONS' run count (pass the same --every to
both sides by giving the processed frames with --frames-from DETECTIONS, the default).
A true box counts when at least MIN_HEIGHT px tall; it is found when a detection of its frame
overlaps it with IoU >= IOU (greedy one-to-one matching, best IoU first). Precision counts
detections of at least MIN_HEIGHT / 2 px matched to any true box (of any size). Prints one
JSON object.
"""
import argparse
import csv
import json
import os
import sys
from collections import defaultdict

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from yolox_goldens import iou  # noqa: E402


def read(path):
    rows = defaultdict(list)
    with open(path) as f:
        for r in csv.DictReader(f):
            rows[int(r["frame"])].append(tuple(float(r[k]) for k in ("x0", "y0", "x1", "y1")))
    return rows


def match(truth, dets, thr):
    pairs = sorted(((iou(t, d), i, j) for i, t in enumerate(truth) for j, d in enumerate(dets)),
                   reverse=True)
    ti, dj = set(), set()
    for v, i, j in pairs:
        if v < thr:
            break
        if i not in ti and j not in dj:
            ti.add(i)
            dj.add(j)
    return ti, dj


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("truth")
    ap.add_argument("detections")
    ap.add_argument("--min-height", type=float, default=24.0)
    ap.add_argument("--iou", type=float, default=0.5)
    ap.add_argument("--frames", type=str, default=None,
                    help="first:step of the processed frames (default: those in the truth, every --every)")
    ap.add_argument("--every", type=int, default=1)
    a = ap.parse_args()
    truth = read(a.truth)
    dets = read(a.detections)
    frames = [f for f in sorted(truth) if f % a.every == 0]
    found = total = tp = npred = 0
    for f in frames:
        t = truth[f]
        d = dets.get(f, [])
        ti, dj = match(t, d, a.iou)
        big = [i for i, b in enumerate(t) if b[3] - b[1] >= a.min_height]
        total += len(big)
        found += sum(1 for i in big if i in ti)
        counted = [j for j, b in enumerate(d) if b[3] - b[1] >= a.min_height / 2]
        npred += len(counted)
        tp += sum(1 for j in counted if j in dj)
    print(json.dumps({
        "frames": len(frames),
        "true_boxes": total,
        "recall": found / total if total else None,
        "detections": npred,
        "precision": tp / npred if npred else None,
        "min_height": a.min_height,
        "iou": a.iou,
    }))


if __name__ == "__main__":
    main()
