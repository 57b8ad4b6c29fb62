"""Aggregating per-vehicle VPs (a real VPout file of BrnoCompSpeed, numpy arrays) against
`vpcal aggregate`, and road measurements against `vpcal scale` / `vpcal measure`."""

from __future__ import annotations

import json

import numpy as np
import pytest

import vpcal

VPOUT = "bcs/vp_outputs/session0_center/VPout_VP1VP2b_pd_aug_25.0ps_10cd_128in_256out_1.0s_2n_4b_256c_6_r60.json"


@pytest.fixture(scope="module")
def vpout(data_dir):
    p = data_dir / VPOUT
    assert p.is_file(), p
    return p


@pytest.mark.parametrize("method", ["robust", "reference"])
def test_aggregating_a_vpout_file_matches_the_cli_bit_for_bit(vpout, cli, tmp_path, method):
    r = cli("aggregate", str(vpout), "--pp", "bcs", "--method", method, "-o", str(tmp_path / "cli.json"))
    assert r.returncode == 0, r.stderr
    cal = vpcal.aggregate(vpout, pp="bcs", method=method)
    cal.save(tmp_path / "py.json")
    assert (tmp_path / "py.json").read_bytes() == (tmp_path / "cli.json").read_bytes()
    assert cal.image_size == (1920, 1080)
    assert cal.to_dict()["settings"]["method"] == method


def test_a_focal_range_replaces_the_prior_as_in_the_cli(vpout, cli, tmp_path):
    args = ("aggregate", str(vpout), "--pp", "bcs", "--focal-range", "1500,2500")
    r = cli(*args, "-o", str(tmp_path / "cli.json"))
    assert r.returncode == 0, r.stderr
    cal = vpcal.aggregate(vpout, pp="bcs", focal_range=(1500, 2500))
    cal.save(tmp_path / "py.json")
    assert (tmp_path / "py.json").read_bytes() == (tmp_path / "cli.json").read_bytes()
    lo, hi = cal.focal_interval_px
    assert 1500 <= lo < cal.focal_px < hi <= 2500
    assert cal.to_dict()["settings"]["focal_range"] == [1500, 2500]


def test_aggregating_arrays_matches_the_cli_on_the_same_records(vpout, cli, tmp_path):
    items = json.loads(vpout.read_text())[:800]
    vp1 = np.array([i["vp1"] for i in items], dtype=float)
    vp2 = np.array([i["vp2"] for i in items], dtype=float)
    scores = np.array([i["score"] for i in items])
    frames = np.array([i["frame_cnt"] for i in items])
    c = np.array([i["box_center"] for i in items])
    s = np.array([i["box_scale"] for i in items])
    boxes = np.concatenate([c - s, c + s], axis=1)
    cal = vpcal.aggregate(vp1=vp1, vp2=vp2, scores=scores, frames=frames, boxes=boxes,
                          image_size=(1920, 1080), pp="bcs", bootstrap=10)
    # The same records as a file with only these fields, through the CLI.
    slim = [
        {"vp1": i["vp1"], "vp2": i["vp2"], "score": i["score"], "frame_cnt": i["frame_cnt"],
         "box_center": i["box_center"], "box_scale": i["box_scale"]}
        for i in items
    ]
    (tmp_path / "slim.json").write_text(json.dumps(slim))
    r = cli("aggregate", str(tmp_path / "slim.json"), "--pp", "bcs", "--image-size", "1920x1080",
            "--bootstrap", "10", "-o", str(tmp_path / "cli.json"))
    assert r.returncode == 0, r.stderr
    a, b = cal.to_dict(), json.loads((tmp_path / "cli.json").read_text())
    for key in ("focal_px", "vp1", "vp2", "K", "R", "evidence", "confidence", "summary"):
        assert a[key] == b[key], key
    # A list of VPout items gives the same.
    again = vpcal.aggregate(slim, image_size=(1920, 1080), pp="bcs", bootstrap=10)
    assert again.to_dict()["vp1"] == a["vp1"]


def test_road_points_and_distances_match_vpcal_measure(vpout, cli, tmp_path):
    cal = vpcal.aggregate(vpout, pp="bcs", bootstrap=0)
    cal.save(tmp_path / "calib.json")
    ref = (900.0, 900.0, 1100.0, 700.0)
    r = cli("scale", str(tmp_path / "calib.json"), "--points", ",".join(map(str, ref)),
            "--distance", "12.5", "-o", str(tmp_path / "scaled.json"))
    assert r.returncode == 0, r.stderr
    scaled = cal.with_scale(ref, 12.5)
    scaled.save(tmp_path / "py_scaled.json")
    assert (tmp_path / "py_scaled.json").read_bytes() == (tmp_path / "scaled.json").read_bytes()
    assert scaled.distances([ref])[0] == pytest.approx(12.5, rel=1e-12)
    # A distance and a lane width: their geometric mean, as the CLI's.
    lane = (800.0, 1000.0, 1200.0, 1000.0)
    r = cli("scale", str(tmp_path / "calib.json"), "--points", ",".join(map(str, ref)),
            "--distance", "12.5", "--lane-points", ",".join(map(str, lane)), "--lane-width",
            "3.5", "-o", str(tmp_path / "scaled2.json"))
    assert r.returncode == 0, r.stderr
    both = cal.with_scale(ref, 12.5, lane_widths=[(lane, 3.5)])
    both.save(tmp_path / "py_scaled2.json")
    assert (tmp_path / "py_scaled2.json").read_bytes() == (tmp_path / "scaled2.json").read_bytes()
    assert both.to_dict()["scale_source"] == "distance_and_lane_width"

    pairs = [(100.0, 1000.0, 1800.0, 950.0), (960.0, 600.0, 960.0, 1079.0),
             (500.0, 800.0, 520.0, 820.0)]
    args = []
    for p in pairs:
        args += ["--points", ",".join(map(str, p))]
    r = cli("measure", str(tmp_path / "scaled.json"), *args, "--json")
    assert r.returncode == 0, r.stderr
    measured = [row["distance"] for row in json.loads(r.stdout)]
    ours = scaled.distances(pairs)
    for m, d in zip(measured, ours):
        assert d == pytest.approx(m, rel=1e-12)
    # A pixel above the horizon: the CLI refuses it (exit 1), the library gives NaN.
    above = (960.0, -400.0, 960.0, 1000.0)
    r = cli("measure", str(tmp_path / "scaled.json"), "--points", ",".join(map(str, above)))
    assert r.returncode == 1 and "outside the" in r.stderr, r.stderr
    assert np.isnan(scaled.distances([above])[0])

    # Road points in metres: their distances are the measured ones, and pixels() inverts them.
    px = np.array([[p[0], p[1]] for p in pairs[:3]] + [[p[2], p[3]] for p in pairs[:3]])
    road = scaled.road_points(px)
    for k in range(3):
        assert np.linalg.norm(road[k] - road[k + 3]) == pytest.approx(measured[k], rel=1e-9)
    assert np.allclose(scaled.pixels(road), px, atol=1e-6)
    assert np.isnan(scaled.road_points([960.0, -400.0])).all()
    # With the automatic scale the records' boxes give (as `vpcal aggregate`), or road units
    # without one: proportional to the known distance's metres.
    auto = cal.road_points(px[:1])
    assert np.allclose(auto / (cal.scale or 1.0) * scaled.scale, road[:1], rtol=1e-9)
