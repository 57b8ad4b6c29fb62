"""The detector and the VP network on numpy frames, crops and boxes; a batch of cameras on
Dask."""

from __future__ import annotations

import csv
import os

import numpy as np
import pytest

import vpcal
from vpcal.batch import calibrate_many

from conftest import render
from test_calibrate import decode


def true_boxes(scene, frame):
    with open(scene / "detections.csv") as f:
        rows = [r for r in csv.DictReader(f) if int(r["frame"]) == frame]
    return np.array([[float(r[k]) for k in ("x0", "y0", "x1", "y1")] for r in rows])


def iou(a, b):
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    i = w * h
    return i / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - i)


def test_the_detector_gives_the_boxes_of_vpcal_detect(scene, cli, tmp_path):
    r = cli("detect", str(scene / "video.mp4"), "--detector", "yolox", "--max-frames", "31",
            "-o", str(tmp_path / "boxes.csv"), "--quiet")
    assert r.returncode == 0, r.stderr
    with open(tmp_path / "boxes.csv") as f:
        rows = list(csv.DictReader(f))
    frames = decode(scene / "video.mp4")
    det = vpcal.Detector("yolox")
    found = 0
    for k in (10, 20, 30):
        boxes = det(frames[k], index=k)
        assert boxes.ndim == 2 and boxes.shape[1] == 5
        theirs = np.array([[float(r[c]) for c in ("x0", "y0", "x1", "y1", "score")]
                           for r in rows if int(r["frame"]) == k]).reshape(-1, 5)
        assert boxes.shape == theirs.shape, k
        order = lambda b: b[np.lexsort((b[:, 1], b[:, 0]))]
        assert np.allclose(order(boxes), order(theirs), atol=1e-3), k
        # The boxes are vehicles: each lies on a true one.
        for b in boxes:
            found += any(iou(t, b) > 0.3 for t in true_boxes(scene, k))
    assert det.name.startswith("yolox")
    assert found >= 1


def test_the_network_on_boxes_gives_the_pipelines_vps(scene):
    cal = vpcal.calibrate(scene / "video.mp4", detector=f"file:{scene / 'detections.csv'}",
                          vehicles=True, bootstrap=0, keep_static=True, max_per_frame=0)
    frames = decode(scene / "video.mp4")
    net = vpcal.Network()
    assert net.model == vpcal._native.BUNDLED_MODEL and net.input_size > 0
    k = 20
    records = [v for v in cal.vehicles if v["frame_cnt"] == k]
    assert records
    boxes = true_boxes(scene, k)
    out = net.predict_boxes(frames[k], boxes)
    assert len(out) == len(boxes) == len(records)
    mine = sorted(out, key=lambda o: tuple(o["crop_box"]))
    theirs = sorted(records, key=lambda r: (r["vp_box"][1], r["vp_box"][0], r["vp_box"][3], r["vp_box"][2]))
    for o, r in zip(mine, theirs):
        assert o["crop_box"] == (r["vp_box"][1], r["vp_box"][0], r["vp_box"][3], r["vp_box"][2])
        assert np.allclose(o["vp1_box"], r["vp1_box"], rtol=1e-4, atol=1e-4)
        assert np.allclose(o["vp2_box"], r["vp2_box"], rtol=1e-4, atol=1e-4)
    # Crops: the same network on the pictures cut out by hand gives finite box-frame VPs.
    crops = [frames[k][int(b[1]):int(b[3]), int(b[0]):int(b[2])] for b in boxes]
    preds = net.predict_crops(crops)
    assert len(preds) == len(crops)
    assert all(np.isfinite(p["vp1_box"]).all() for p in preds)


def test_a_batch_of_cameras_on_dask_matches_one_by_one(tmp_path, vpcal_bin):
    clips = [render(vpcal_bin, tmp_path, seed, f"cam{seed}") / "video.mp4" for seed in (1, 2, 4)]
    clips.append(tmp_path / "missing.mp4")
    options = vpcal.Options(bootstrap=10)
    seen = []
    results = calibrate_many(clips, options, n_workers=min(2, os.cpu_count() or 1),
                             on_result=seen.append)
    assert [r.source for r in results] == [str(c) for c in clips]
    assert len(seen) == len(clips)
    assert not results[-1].ok and "missing.mp4" in results[-1].error
    for clip, r in zip(clips[:-1], results[:-1]):
        try:
            alone = vpcal.calibrate(clip, options)
        except vpcal.NotCalibrated as e:
            assert r.not_calibrated and r.error == str(e)
            continue
        assert r.ok, r.error
        a, b = r.calibration.to_dict(), alone.to_dict()
        for key in ("focal_px", "vp1", "vp2", "evidence", "confidence"):
            assert a[key] == b[key], key
