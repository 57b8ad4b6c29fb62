"""Fixtures of the vpcal Python tests: the CLI binary (to compare with), synthetic clips
rendered by it, the real data folder."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

# A 320x240, 40-frame highway clip whose VP2 is near enough for the edgelets to measure the
# focal length (the focal prior alone would say 441 px, +34 %).
SCENE_ARGS = [
    "--layout", "highway", "--frames", "40", "--width", "320", "--height", "240",
    "--focal", "330", "--yaw", "-30", "--pitch", "20", "--cam-height", "10", "--roll", "1",
    "--supersample", "1",
]


def _binary() -> str:
    env = os.environ.get("VPCAL_BIN")
    if env:
        return env
    for profile in ("debug", "release"):
        p = ROOT / "target" / profile / "vpcal"
        if p.is_file():
            return str(p)
    found = shutil.which("vpcal")
    if found:
        return found
    raise RuntimeError(
        "the vpcal binary is needed to compare with the CLI: set VPCAL_BIN or build it "
        "(cargo build -p vpcal)"
    )


@pytest.fixture(scope="session")
def vpcal_bin() -> str:
    return _binary()


def run_cli(binary: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([binary, *args], capture_output=True, text=True, check=False)


@pytest.fixture(scope="session")
def cli():
    b = _binary()
    return lambda *args: run_cli(b, *args)


def render(binary: str, out: Path, seed: int, name: str) -> Path:
    r = run_cli(binary, "synth", "scene", *SCENE_ARGS, "--seed", str(seed), "--name", name, "-o", str(out))
    assert r.returncode == 0, r.stderr
    return out / "dataset" / name


@pytest.fixture(scope="session")
def scene(tmp_path_factory, vpcal_bin):
    """The synthetic clip's folder (video.mp4, detections.csv, camera.json)."""
    d = render(vpcal_bin, tmp_path_factory.mktemp("scene"), 3, "py")
    return d


@pytest.fixture(scope="session")
def truth(scene):
    return json.loads((scene / "camera.json").read_text())


@pytest.fixture(scope="session")
def data_dir() -> Path:
    d = Path(os.environ.get("VPCAL_DATA", str(ROOT / ".." / "shared" / "data")))
    if not d.is_dir():
        raise RuntimeError(f"the real data folder {d} is missing (set VPCAL_DATA)")
    return d
