#!/usr/bin/env python3
"""Independent numpy implementation of the BrnoCompSpeed speed evaluation.

Written from the official protocol (`code/eval.py` of github.com/JakubSochor/BrnoCompSpeed,
DESIGN.md §8) for Python 3 + numpy, independently of vpcal's Rust code
(`crates/vpcal-formats/src/bcs_speed.rs`), to produce the numbers that
`crates/vpcal-formats/tests/real_data.rs` checks `bcs_speed` against.

Protocol, per video:
  1. prefilter the system's cars: keep a car first seen (frames[0] / fps) before the latest
     last GT crossing; drop its points not strictly inside the image by more than 10 px
     (1920x1080); keep cars with more than 5 points left, every point inside the lane-divider
     span, no point in an invalid lane, and at least 6 points between measurementLines[0] and
     measurementLines[-1] (inclusive of the lines);
  2. crossings of measurementLines[-1] (start) and measurementLines[0] (end): the 6 points
     closest to the line (stable order), least squares y = a x + b through them, the crossing
     point where that line meets the measurement line; frame numbers regressed on the distance
     (along the fitted line) of the points' projections from where the fitted line meets y = 0,
     evaluated at the crossing point's distance. A non-finite crossing, or one outside the lane
     span, makes the car an "error" (counted as a false positive);
  3. speeds: "full" = scale * |X(start) - X(end)| / (|frame_end - frame_start| / fps) * 3.6;
     "median" = median over i of scale * |X_i - X_{i+5}| / (|f_i - f_{i+5}| / fps) * 3.6 over all
     the car's kept points; the car's lane is the lane of its end crossing, its time
     frame_end / fps;
  4. each GT car (valid or not) matches the system car in one of its lanes whose end time is
     closest to the GT car's last listed crossing (intersections[-1]), if closer than 0.2 s;
  5. errors over matched valid cars (absolute km/h, relative %), recall = matched valid / valid,
     false positives = errors + unmatched system cars whose end time lies in
     [min, max) of the GT cars' last crossing times.
Pooled: errors concatenated, recall averaged over videos, false positives summed.

Road plane (BCS convention): camera centre (px, py, 0), ray (p - pp, f), plane n.X + 10 = 0 with
n the unit direction of vp3. With --camera-truth FILE the camera of each video is FILE's
cameras[video] {vp1, vp2, pp} and the scale the weighted median of d_i / d^_i with weights
d^_i / d_i over the video's taped distances (the minimiser of the mean relative distance error;
the lower median on ties), instead of the system file's calibration.

Usage:
  python3 scripts/bcs_speed_reference.py DATASET RESULTS SYSTEM [--mode median|full]
      [--camera-truth FILE] [--videos session0_center ...]
Needs numpy (gt_data.pkl holds numpy arrays): e.g. python3 -m venv /tmp/v && /tmp/v/bin/pip
install numpy. Prints one JSON line per video and one "pooled" line.
"""
import argparse
import json
import os
import pickle

import numpy as np

WIDTH, HEIGHT = 1920.0, 1080.0
BORDER = 10.0
AROUND = 6
OFFSET = 5
MAX_DT = 0.2


def h(p):
    p = np.asarray(p, dtype=float)
    return p / p[2] if p.shape[0] == 3 else np.array([p[0], p[1], 1.0])


def side_product(p, a, b):
    """<= 0 when homogeneous point p lies between lines a and b (or on one)."""
    return np.dot(p, a) * np.dot(p, b) * np.dot(a[:2], b[:2])


def lane_of(p, lanes):
    for i in range(len(lanes) - 1):
        if side_product(p, lanes[i], lanes[i + 1]) <= 0:
            return i
    return None


class Camera:
    def __init__(self, vp1, vp2, pp):
        vp1, vp2, self.pp = (np.asarray(v, dtype=float)[:2] for v in (vp1, vp2, pp))
        self.f = np.sqrt(-np.dot(vp1 - self.pp, vp2 - self.pp))
        d3 = np.cross(np.append(vp1 - self.pp, self.f), np.append(vp2 - self.pp, self.f))
        vp3 = d3[:2] / d3[2] * self.f + self.pp
        n = np.append(vp3 - self.pp, self.f)
        self.n = n / np.linalg.norm(n)

    def road(self, p):
        p = h(p)
        c = np.array([self.pp[0], self.pp[1], 0.0])
        r = np.array([p[0] - self.pp[0], p[1] - self.pp[1], self.f])
        return c + (-(self.n @ c + 10.0) / (self.n @ r)) * r


def least_squares(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    with np.errstate(all="ignore"):
        a = np.sum((x - x.mean()) * (y - y.mean())) / np.sum((x - x.mean()) ** 2)
    return a, y.mean() - a * x.mean()


def crossing(line, xs, ys, frames):
    """(crossing point [x, y, 1], crossing frame) of a track with a line."""
    pts = np.column_stack([xs, ys, np.ones(len(xs))])
    dist = np.abs(pts @ line) / np.hypot(line[0], line[1])
    near = np.argsort(dist, kind="stable")[:AROUND]
    p, fr = pts[near], np.asarray(frames, float)[near]
    a, b = least_squares(p[:, 0], p[:, 1])
    fit = np.array([a, -1.0, b])
    with np.errstate(all="ignore"):
        x = np.cross(fit, line)
        x = x / x[2]
        origin = np.array([-b / a, 0.0])  # the fitted line at y = 0
        u = np.array([1.0, a]) / np.hypot(1.0, a)  # its direction
        proj = origin + np.outer((p[:, :2] - origin) @ u, u)
        d = np.linalg.norm(proj - origin, axis=1)
        s, c = least_squares(d, fr)
        t = s * np.linalg.norm(x[:2] - origin) + c
    return x, t


def prefilter(cars, gt):
    fps = gt["fps"]
    t_max = max(c["intersections"][-1]["videoTime"] for c in gt["cars"])
    lanes = [np.asarray(l, float) for l in gt["laneDivLines"]]
    lines = [np.asarray(l, float) for l in gt["measurementLines"]]
    invalid = set(int(i) for i in gt["invalidLanes"])
    kept = []
    for car in cars:
        if not isinstance(car["posX"], list) or not car["frames"]:
            continue
        if not car["frames"][0] / fps < t_max:
            continue
        x, y, f = (np.asarray(car[k], float) for k in ("posX", "posY", "frames"))
        inside = (x > BORDER) & (x < WIDTH - BORDER) & (y > BORDER) & (y < HEIGHT - BORDER)
        x, y, f = x[inside], y[inside], f[inside]
        if len(f) <= 5:
            continue
        pts = [np.array([a, b, 1.0]) for a, b in zip(x, y)]
        lane_ids = [lane_of(p, lanes) for p in pts]
        if any(l is None for l in lane_ids):
            continue
        if invalid and any(l in invalid for l in lane_ids):
            continue
        between = sum(1 for p in pts if side_product(p, lines[0], lines[-1]) <= 0)
        if between < 6:
            continue
        kept.append({"id": car["id"], "x": x, "y": y, "f": f})
    return kept


def measure(cars, gt, cam, scale):
    fps = gt["fps"]
    lanes = [np.asarray(l, float) for l in gt["laneDivLines"]]
    lines = [np.asarray(l, float) for l in gt["measurementLines"]]
    done, errors = [], 0
    for car in cars:
        s_pt, s_fr = crossing(lines[-1], car["x"], car["y"], car["f"])
        e_pt, e_fr = crossing(lines[0], car["x"], car["y"], car["f"])
        vals = np.concatenate([s_pt, e_pt, [s_fr, e_fr]])
        if not np.all(np.isfinite(vals)) or lane_of(e_pt, lanes) is None \
                or lane_of(s_pt, lanes) is None:
            errors += 1
            continue
        with np.errstate(all="ignore"):
            full = scale * np.linalg.norm(cam.road(s_pt) - cam.road(e_pt)) \
                / (abs(e_fr - s_fr) / fps) * 3.6
            world = np.array([cam.road([a, b]) for a, b in zip(car["x"], car["y"])])
            steps = scale * np.linalg.norm(world[:-OFFSET] - world[OFFSET:], axis=1) \
                / (np.abs(car["f"][:-OFFSET] - car["f"][OFFSET:]) / fps) * 3.6
        done.append({"id": car["id"], "lane": lane_of(e_pt, lanes), "t": e_fr / fps,
                     "full": float(full), "median": float(np.median(steps))})
    return done, errors


def evaluate(gt, system_cars, cam, scale, mode):
    cars, errors = measure(prefilter(system_cars, gt), gt, cam, scale)
    matched_ids, abs_err, rel_err = set(), [], []
    valid = matched_valid = 0
    for g in gt["cars"]:
        t = g["intersections"][-1]["videoTime"]
        cands = [c for c in cars if c["lane"] in g["laneIndex"]]
        best = min(cands, key=lambda c: abs(c["t"] - t)) if cands else None
        ok = best is not None and abs(best["t"] - t) < MAX_DT
        valid += bool(g["valid"])
        if ok:
            matched_ids.add(best["id"])
            if g["valid"]:
                matched_valid += 1
                e = abs(g["speed"] - best[mode])
                abs_err.append(e)
                rel_err.append(e / g["speed"] * 100.0)
    last = [g["intersections"][-1]["videoTime"] for g in gt["cars"]]
    lo, hi = min(last), max(last)
    fp = errors + sum(1 for c in cars if lo <= c["t"] < hi and c["id"] not in matched_ids)
    return {"cars": len(cars), "errors": errors, "matched": matched_valid, "valid": valid,
            "recall": matched_valid / valid if valid else None, "false_positives": fp,
            "abs": abs_err, "rel": rel_err}


def stats(v):
    if not v:
        return None
    v = np.asarray(v)
    return {"n": int(v.size), "mean": float(v.mean()), "median": float(np.median(v)),
            "p95": float(np.percentile(v, 95)), "max": float(v.max())}


def fitted_scale(cam, meas):
    est = np.array([np.linalg.norm(cam.road(m["p1"]) - cam.road(m["p2"])) for m in meas])
    d = np.array([m["distance"] for m in meas], float)
    ratio, w = d / est, est / d
    order = np.argsort(ratio, kind="stable")
    acc = np.cumsum(w[order])
    return float(ratio[order][np.argmax(acc >= w.sum() / 2.0)])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("results")
    ap.add_argument("system")
    ap.add_argument("--mode", choices=["median", "full"], default="median")
    ap.add_argument("--camera-truth")
    ap.add_argument("--videos", nargs="*")
    a = ap.parse_args()
    truth = None
    if a.camera_truth:
        with open(a.camera_truth) as f:
            truth = json.load(f)["cameras"]
    videos = a.videos or sorted(
        v for v in os.listdir(a.dataset)
        if os.path.isfile(os.path.join(a.dataset, v, "gt_data.pkl")))
    pooled_abs, pooled_rel, recalls, fps_total = [], [], [], 0
    for video in videos:
        sys_path = os.path.join(a.results, video, "system_%s.json" % a.system)
        if not os.path.isfile(sys_path):
            continue
        with open(os.path.join(a.dataset, video, "gt_data.pkl"), "rb") as f:
            gt = pickle.load(f, encoding="latin1")
        with open(sys_path) as f:
            system = json.load(f)
        if truth is not None:
            c = truth[video]
            cam = Camera(c["vp1"], c["vp2"], c["pp"])
            scale = fitted_scale(cam, gt["distanceMeasurement"])
        else:
            c = system["camera_calibration"]
            cam = Camera(c["vp1"], c["vp2"], c["pp"])
            scale = c["scale"]
        r = evaluate(gt, system["cars"], cam, scale, a.mode)
        pooled_abs += r["abs"]
        pooled_rel += r["rel"]
        if r["recall"] is not None:
            recalls.append(r["recall"])
        fps_total += r["false_positives"]
        out = {"video": video, "scale": scale, "abs": stats(r["abs"]), "rel": stats(r["rel"])}
        out.update({k: r[k] for k in ("cars", "errors", "matched", "valid", "recall",
                                      "false_positives")})
        print(json.dumps(out))
    print(json.dumps({"video": "pooled", "abs": stats(pooled_abs), "rel": stats(pooled_rel),
                      "recall": float(np.mean(recalls)) if recalls else None,
                      "false_positives": fps_total}))


if __name__ == "__main__":
    main()
