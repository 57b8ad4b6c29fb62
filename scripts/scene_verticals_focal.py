#!/usr/bin/env python3
"""The focal length from the scene's vertical lines (VP3), where the camera is known.

Poles, posts, walls and buildings stand vertical, so their image lines meet at VP3, the road
normal's vanishing point; with VP1 and the horizon's roll, VP3 lies at f^2 / d beyond the
principal point (d its distance from the horizon), so it measures f without VP2. This runs
`examples/scene_verticals.rs` (the line segments of a picture and the fit calibrate uses,
`vpcal_geom::aggregate::verticals`) on each view's picture with its true VP1 and roll, and
compares the fit with the true focal length.

  scripts/scene_verticals_focal.py bcs            BrnoCompSpeed sessions 0-3: each screen.png
                                                  (unmasked, as calibrate sees the frame),
                                                  against camera_truth.json
  scripts/scene_verticals_focal.py suite SUITE    the synthetic suite (SUITE from
                                                  `vpcal synth suite`): calibrate's
                                                  --background of each scene, against its
                                                  camera.json

Prints per view the fit over the truth, the bootstrap's 68 % range over the truth, and the
error in standard deviations of the cue's likelihood (the bootstrap's spread with the model
error VERTICALS_MODEL_LOG_SD); then the identified fits' ln errors (median, mean, rms).
Needs numpy. VPCAL: the binary for the suite (default target/release/vpcal).
"""
import glob
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
DATA = os.environ.get("VPCAL_DATA", os.path.join(ROOT, "..", "shared", "data"))
MODEL_LOG_SD = 0.14  # vpcal_geom::aggregate::verticals::VERTICALS_MODEL_LOG_SD


def example():
    subprocess.run(["cargo", "build", "--release", "--quiet", "--example", "scene_verticals"], cwd=ROOT,
                   check=True)
    return os.path.join(ROOT, "target", "release", "examples", "scene_verticals")


def run(exe, picture, vp1, roll):
    out = subprocess.run([exe, picture, str(vp1[0]), str(vp1[1]), str(math.degrees(roll))], check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out)


def row(name, true_f, r, true_roll=None):
    f = r["fit"]
    if f is None:
        print(f"{name:22s} true {true_f:6.0f}  segments {r['segments']:5d}  no candidate")
        return None
    lo, hi = f["bootstrap_px"]
    b = 0.5 * abs(math.log(hi / lo))
    sd = math.sqrt(b * b + MODEL_LOG_SD ** 2)
    e = math.log(f["focal_px"] / true_f)
    print(f"{name:22s} true {true_f:6.0f}  fit {f['focal_px']:6.0f}  ratio {f['focal_px'] / true_f:5.2f}  "
          f"boot {lo / true_f:4.2f}-{hi / true_f:4.2f}  z {e / sd:5.2f}  segments {r['segments']:5d} "
          f"candidates {f['candidates']:4d} supporting {f['supporting']:3d}  "
          f"{'' if f['identified'] else 'not identified'}")
    own = f.get("own_roll_deg")
    if own is not None and true_roll is not None:
        d = own - math.degrees(true_roll)
        OWN_ROLLS.append((name, d, f["own_roll_sd_deg"]))
        spread = f["own_roll_sd_deg"]
        spread = "not measured (it could not contradict)" if spread is None else f"{spread:.2f}"
        print(f"{'':22s} own roll (no prior) {own:+6.2f} deg, minus the true {d:+5.2f}, spread {spread}")
    return e if f["identified"] else None


# The verticals' own roll (gravity's horizon) against the true road horizon's: (view, own minus
# true, degrees, its resamples' spread).
OWN_ROLLS = []


def report(errors, total):
    e = np.array([x for x in errors if x is not None])
    if len(e) == 0:
        print(f"identified 0 of {total}")
        return
    print(f"identified {len(e)} of {total}: ln(fit / truth) median {np.median(e):+.3f}, mean {e.mean():+.3f}, "
          f"|.| median {np.median(np.abs(e)):.3f}, rms {math.sqrt(np.mean(e ** 2)):.3f}")
    if OWN_ROLLS:
        d = np.array([x[1] for x in OWN_ROLLS])
        print(f"own roll identified on {len(d)} of {total}: minus the true, median {np.median(d):+.2f}, "
              f"|.| median {np.median(np.abs(d)):.2f}, max |.| {np.abs(d).max():.2f} deg")


def bcs():
    exe = example()
    cameras = json.load(open(os.path.join(DATA, "bcs", "camera_truth.json")))["cameras"]
    errors = []
    for name, c in cameras.items():
        vp1, vp2, pp = (np.array(c[k]) for k in ("vp1", "vp2", "pp"))
        true_f = math.sqrt(-np.dot(vp1 - pp, vp2 - pp))
        roll = math.atan2(vp2[1] - vp1[1], vp2[0] - vp1[0])
        errors.append(row(name, true_f, run(exe, os.path.join(DATA, "bcs", "dataset", name, "screen.png"), vp1,
                                            roll), roll))
    report(errors, len(cameras))


def suite(folder):
    exe = example()
    vpcal = os.environ.get("VPCAL", os.path.join(ROOT, "target", "release", "vpcal"))
    errors = []
    scenes = sorted(glob.glob(os.path.join(folder, "dataset", "*/")))
    with tempfile.TemporaryDirectory() as tmp:
        for d in scenes:
            name = os.path.basename(d.rstrip("/"))
            picture = os.path.join(tmp, name + ".png")
            subprocess.run([vpcal, "calibrate", os.path.join(d, "video.mp4"), "--detections",
                            os.path.join(d, "detections.csv"), "--quiet", "-o", os.path.join(tmp, name + ".json"),
                            "--background", picture], capture_output=True)
            cam = json.load(open(os.path.join(d, "camera.json")))
            if not os.path.exists(picture):
                print(f"{name:22s} no background")
                continue
            vp1, vp2 = np.array(cam["vp1"]), np.array(cam["vp2"])
            roll = math.atan2(vp2[1] - vp1[1], vp2[0] - vp1[0])
            errors.append(row(name, cam["focal_px"], run(exe, picture, vp1, roll), roll))
    report(errors, len(scenes))


if __name__ == "__main__":
    if len(sys.argv) >= 2 and sys.argv[1] == "bcs":
        bcs()
    elif len(sys.argv) >= 3 and sys.argv[1] == "suite":
        suite(sys.argv[2])
    else:
        sys.exit(__doc__)
