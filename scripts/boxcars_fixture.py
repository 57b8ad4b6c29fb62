#!/usr/bin/env python3
"""A small dataset in the BoxCars116k format, for vpcal-data's loader tests.

BoxCars116k (Sochor et al.) is distributed on request only, so the tests run on files that this
script writes in the same format (DESIGN.md section 6), the way the original Python-2 files were
written: protocol 2, byte strings and ASCII text as Python-2 `str`, numpy arrays through
numpy.core.multiarray._reconstruct.

  dataset.pkl  {"cameras": {name: {"pp", "vp1", "vp2", "vp3", "focal"}},
                "samples": [ {"camera", "to_camera", "annotation",
                              "instances": [{"3DBB" (8x2 f8, frame px), "3DBB_offset" (2, f8),
                                             "2DBB" (x, y, w, h), "instance_id", "path"}]} ]}
  atlas.pkl    atlas[vehicle][instance] = the JPEG bytes of the crop: a uint8 numpy array of shape
               (n, 1), as cv2.imencode returns it (every 7th vehicle: a plain byte string)

Every vehicle is a box aligned with the road axes of its camera, so its projected 3D box edges
meet exactly at the camera's VP1 (length), VP2 (width) and VP3 (height). Corner order as in
BoxCars: 0-3 go round the top face (0 front-left, 1 front-right, 2 rear-right, 3 rear-left),
4-7 lie below 0-3; edges 0-3, 1-2, 4-7, 5-6 point to VP1, 0-1, 3-2, 4-5, 7-6 to VP2.

The crops are rendered (faces of the box in flat colours over a textured road) and JPEG-encoded.

Usage (numpy and Pillow needed, e.g. in a throwaway venv):
  python scripts/boxcars_fixture.py                    # the committed test fixture
  python scripts/boxcars_fixture.py --out DIR --vehicles 20000 --seed 1
                                                       # a large file for memory measurements
"""
import argparse
import io
import math
import os
import sys

import numpy as np
from PIL import Image, ImageDraw, ImageFilter

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pickle_fixtures import Py2Pickler  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_OUT = os.path.join(ROOT, "crates", "vpcal-data", "tests", "fixtures", "boxcars")

FRAME_W, FRAME_H = 1920, 1080
PP = np.array([FRAME_W / 2 + 0.5, FRAME_H / 2 + 0.5])


def rotation(pitch, yaw, roll):
    """Camera-from-world rotation. World: X along the road, Y across, Z up. Camera: x right,
    y down, z forward. The camera looks along the road (turned by `yaw`), tilted down by
    `pitch`."""
    # base: world X -> camera z (forward), world Y -> camera -x, world Z -> camera -y
    base = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    cy, sy = math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])  # yaw about world Z
    cp, sp = math.cos(pitch), math.sin(pitch)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])  # pitch about camera x
    cr, sr = math.cos(roll), math.sin(roll)
    rzc = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])  # roll about camera z
    return rzc @ rx @ base @ rz


class Camera:
    def __init__(self, name, focal, pitch, yaw, roll, height):
        self.name = name
        self.focal = focal
        self.R = rotation(pitch, yaw, roll)
        self.C = np.array([0.0, 0.0, height])

    def project(self, X):
        Xc = self.R @ (np.asarray(X, dtype=float) - self.C)
        return PP + self.focal * Xc[:2] / Xc[2]

    def depth(self, X):
        return (self.R @ (np.asarray(X, dtype=float) - self.C))[2]

    def vp(self, axis):
        d = self.R[:, axis]
        return PP + self.focal * d[:2] / d[2]

    def record(self):
        return {
            "pp": PP.copy(),
            "vp1": self.vp(0),
            "vp2": self.vp(1),
            "vp3": self.vp(2),
            "focal": float(self.focal),
        }


def box_corners(x, y, length, width, height, heading):
    """BoxCars corner order; `heading` +1 drives along +X (front at larger X), -1 along -X."""
    fx = x + heading * length / 2
    rx = x - heading * length / 2
    ly = y + heading * width / 2  # left side of the vehicle
    ry = y - heading * width / 2
    top = [(fx, ly, height), (fx, ry, height), (rx, ry, height), (rx, ly, height)]
    bottom = [(px, py, 0.0) for (px, py, _) in top]
    return top + bottom


FACES = [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (3, 2, 6, 7), (1, 2, 6, 5), (0, 3, 7, 4)]
# roof, floor, front, rear, right and left side: muted, car-like, so that drawn annotations stand out
FACE_COLOURS = [(170, 172, 180), (30, 30, 32), (95, 105, 125), (120, 95, 85), (75, 85, 100),
                (105, 110, 95)]


def render_crop(rng, cam, corners3d, bb, offset, size):
    w, h = size
    # textured road background
    base = rng.integers(70, 130)
    noise = rng.normal(0, 12, (h, w, 1)) + base
    img = np.clip(np.concatenate([noise, noise + 5, noise + 10], axis=2), 0, 255).astype(np.uint8)
    im = Image.fromarray(img, "RGB").filter(ImageFilter.GaussianBlur(0.7))
    draw = ImageDraw.Draw(im)
    pts = [tuple(p - offset) for p in bb]
    # painter's algorithm: farthest faces first
    depths = [np.mean([cam.depth(corners3d[i]) for i in f]) for f in FACES]
    for fi in np.argsort(depths)[::-1]:
        face = FACES[fi]
        colour = tuple(int(c) for c in np.clip(np.array(FACE_COLOURS[fi]) + rng.integers(-20, 20, 3), 0, 255))
        draw.polygon([pts[i] for i in face], fill=colour, outline=(20, 20, 20))
    buf = io.BytesIO()
    im.save(buf, format="JPEG", quality=90)
    return buf.getvalue()


def make(out, vehicles, seed, max_instances):
    rng = np.random.default_rng(seed)
    cams = [
        Camera("cam_a", 1400.0, math.radians(18), math.radians(25), math.radians(2), 8.0),
        Camera("cam_b", 950.0, math.radians(28), math.radians(-35), math.radians(-3), 11.0),
        Camera("cam_c", 2100.0, math.radians(12), math.radians(55), math.radians(1), 6.5),
    ]
    samples = []
    atlas = []
    for vid in range(vehicles):
        cam = cams[vid % len(cams)]
        length = rng.uniform(3.8, 5.2)
        width = rng.uniform(1.6, 1.95)
        height = rng.uniform(1.35, 1.9)
        heading = 1 if rng.random() < 0.6 else -1
        n_inst = 1 + (vid % max_instances)
        instances = []
        crops = []
        for iid in range(n_inst):
            for _ in range(100):
                # a point on the road in front of the camera, in view
                dist = rng.uniform(18.0, 45.0)
                lateral = rng.uniform(-6.0, 6.0)
                # world position from the camera's viewing direction on the ground
                fwd = cam.R.T @ np.array([0.0, 0.0, 1.0])
                fwd[2] = 0.0
                fwd /= np.linalg.norm(fwd)
                side = np.array([-fwd[1], fwd[0], 0.0])
                p = cam.C[:2] + dist * fwd[:2] + lateral * side[:2]
                corners3d = box_corners(p[0], p[1], length, width, height, heading)
                if min(cam.depth(c) for c in corners3d) < 2.0:
                    continue
                bb = np.array([cam.project(c) for c in corners3d], dtype=np.float64)
                lo, hi = bb.min(axis=0), bb.max(axis=0)
                if lo[0] < 0 or lo[1] < 0 or hi[0] > FRAME_W or hi[1] > FRAME_H:
                    continue
                if (hi - lo).min() < 24 or (hi - lo).max() > 400:
                    continue
                break
            else:
                raise RuntimeError("could not place vehicle %d" % vid)
            margin = rng.integers(3, 12, 2)
            offset = np.floor(lo) - margin
            size = (int(math.ceil(hi[0] - offset[0])) + int(margin[0]),
                    int(math.ceil(hi[1] - offset[1])) + int(margin[1]))
            jpeg = render_crop(rng, cam, corners3d, bb, offset, size)
            instances.append({
                "3DBB": bb,
                "3DBB_offset": offset.astype(np.float64),
                "2DBB": np.array([lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]]),
                "instance_id": iid,
                "path": "%s/%06d/%03d.png" % (cam.name, vid, iid),
            })
            if vid % 7 == 3:
                crops.append(jpeg)  # a Python-2 byte string
            else:
                crops.append(np.frombuffer(jpeg, dtype=np.uint8).reshape(-1, 1).copy())
        samples.append({
            "camera": cam.name,
            "to_camera": heading < 0,
            "annotation": "synthetic box %d" % vid,
            "instances": instances,
        })
        atlas.append(crops)
    dataset = {"cameras": {c.name: c.record() for c in cams}, "samples": samples}
    os.makedirs(out, exist_ok=True)
    for name, obj in (("dataset.pkl", dataset), ("atlas.pkl", atlas)):
        path = os.path.join(out, name)
        with open(path + ".tmp", "wb") as f:
            Py2Pickler(f, protocol=2).dump(obj)
        os.replace(path + ".tmp", path)
    total = sum(len(s["instances"]) for s in samples)
    print("%s: %d vehicles, %d instances, atlas %.1f MB" % (
        out, vehicles, total, os.path.getsize(os.path.join(out, "atlas.pkl")) / 1e6))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=DEFAULT_OUT)
    ap.add_argument("--vehicles", type=int, default=30)
    ap.add_argument("--max-instances", type=int, default=3)
    ap.add_argument("--seed", type=int, default=20211)
    args = ap.parse_args()
    make(args.out, args.vehicles, args.seed, args.max_instances)


if __name__ == "__main__":
    main()
