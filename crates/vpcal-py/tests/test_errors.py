"""Bad input is a Python exception with the CLI's message: which file, field or setting, and
what was expected."""

from __future__ import annotations

import json

import numpy as np
import pytest

import vpcal


def test_a_missing_input_names_the_file(tmp_path):
    missing = tmp_path / "nope.mp4"
    with pytest.raises(vpcal.VpcalError, match="nope.mp4") as e:
        vpcal.calibrate(missing)
    assert "cannot open input" in str(e.value)


def test_the_same_message_as_the_cli(tmp_path, cli):
    missing = tmp_path / "nope.mp4"
    r = cli("calibrate", str(missing), "-o", str(tmp_path / "c.json"))
    assert r.returncode == 1
    with pytest.raises(vpcal.VpcalError) as e:
        vpcal.calibrate(missing)
    assert r.stderr.strip() == f"error: {e.value}"


@pytest.mark.parametrize(
    "settings, error, message",
    [
        ({"every": 0}, vpcal.VpcalError, "every"),
        ({"batch": 0}, vpcal.VpcalError, "--batch must be at least 1"),
        ({"detector": "magic"}, ValueError, "unknown detector `magic`"),
        ({"method": "median"}, ValueError, "unknown aggregation method"),
        ({"pp": "middle"}, ValueError, "pp: expected `centre`, `bcs` or a point"),
        ({"every": "two"}, TypeError, "every: expected an int, got str"),
        ({"focal": -3.0}, vpcal.VpcalError, "--focal -3"),
        ({"focal_range": (2000.0, 1000.0)}, vpcal.VpcalError, "--focal-range 2000,1000"),
        ({"focal": 900.0, "focal_range": (500.0, 2000.0)}, vpcal.VpcalError, "give one"),
        ({"road_mask": "m.png"}, vpcal.VpcalError, "--road-mask applies to the motion detector"),
        ({"scale_points": (1, 2, 3, 4)}, ValueError, "scale_points and scale_distance go together"),
        ({"colour": "red"}, TypeError, "unknown option 'colour'"),
        ({"markings": (9.0, 0.0)}, ValueError, "markings: expected the dash period"),
        ({"markings": "xx"}, ValueError, r"markings: expected .* or one of the standards cz"),
        ({"max_records": 0}, vpcal.VpcalError, "--max-records must be at least 1"),
        ({"min_crop_px": -5.0}, vpcal.VpcalError, "--min-crop-px -5"),
        ({"min_crop_px": "big"}, TypeError, "min_crop_px: expected a number"),
    ],
)
def test_bad_settings_name_the_setting(scene, settings, error, message):
    with pytest.raises(error, match=message):
        vpcal.calibrate(scene / "video.mp4", **settings)


def test_bad_frames_name_the_frame():
    good = np.zeros((48, 64, 3), dtype=np.uint8)
    with pytest.raises(ValueError, match=r"frame 1: expected an H x W x 3 array \(RGB\), got shape \(48, 64\)"):
        vpcal.calibrate([good, good[:, :, 0]], fps=25)
    with pytest.raises(TypeError, match="frame 0: expected dtype uint8"):
        vpcal.calibrate([good.astype(np.float32)], fps=25)
    with pytest.raises(ValueError, match="frame 1: 32x48 pixels, but the first frame is 64x48"):
        vpcal.calibrate([good, good[:, :32]], fps=25)
    with pytest.raises(TypeError, match="expected a path"):
        vpcal.calibrate(42)
    with pytest.raises(vpcal.VpcalError, match="no pictures"):
        vpcal.calibrate([], fps=25)
    # A generator cannot be read twice; the motion detector's replay says so.
    with pytest.raises(ValueError, match="one-shot iterator"):
        vpcal.calibrate((good for _ in range(80)), fps=25, detector="motion")


def test_footage_without_vehicles_is_not_calibrated():
    frames = np.zeros((10, 48, 64, 3), dtype=np.uint8)
    with pytest.raises(vpcal.NotCalibrated) as e:
        vpcal.calibrate(frames, fps=25)
    reason = str(e.value)
    text = e.value.calibration_file
    assert json.loads(text)["status"] == "not_enough_evidence"
    assert json.loads(text)["reason"] == reason
    assert reason.startswith("not enough evidence")
    cal = vpcal.calibrate(frames, fps=25, raise_on_failure=False)
    assert not cal.ok and cal.reason == reason and cal.focal_px is None


def test_bad_records_name_the_item_and_field(tmp_path):
    p = tmp_path / "vp.json"
    p.write_text(json.dumps([{"vp1": [1, 2], "vp2": [3, 4], "score": 1, "frame_cnt": 0},
                             {"vp1": [1], "vp2": [3, 4], "score": 1, "frame_cnt": 0}]))
    with pytest.raises(vpcal.VpcalError, match=r"item \[1\]\.vp1"):
        vpcal.aggregate(p, image_size=(64, 48))
    p.write_text(json.dumps([{"vp1": [1, 2], "vp2": [3, 4], "score": 1, "frame_cnt": 0}]))
    with pytest.raises(vpcal.VpcalError, match="the frame size is not known"):
        vpcal.aggregate(p)
    with pytest.raises(vpcal.NotCalibrated):
        vpcal.aggregate(p, image_size=(64, 48))
    with pytest.raises(ValueError, match=r"vp2: expected an 3 x 2 array"):
        vpcal.aggregate(vp1=np.zeros((3, 2)), vp2=np.zeros((2, 2)), image_size=(64, 48))
    with pytest.raises(TypeError, match="image_size"):
        vpcal.aggregate(vp1=np.zeros((3, 2)), vp2=np.zeros((3, 2)))


def test_bad_calibration_files_name_the_field(tmp_path):
    p = tmp_path / "c.json"
    p.write_text(json.dumps({"format": "vpcal-calibration/2", "status": "calibrated",
                             "image_size": [64, 48], "vp1": [1, 2], "pp": [0, 0]}))
    with pytest.raises(vpcal.VpcalError, match="c.json"):
        vpcal.load(p)
    with pytest.raises(vpcal.VpcalError, match="nothing.json"):
        vpcal.load(tmp_path / "nothing.json")


def test_a_failing_progress_callback_is_raised(scene):
    def boom(done, total, boxes):
        if done == 3:
            raise RuntimeError("stop at 3")

    with pytest.raises(RuntimeError, match="stop at 3"):
        vpcal.calibrate(scene / "video.mp4", progress=boom, bootstrap=0)
