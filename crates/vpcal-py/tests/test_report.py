"""The HTML report from Python (`Calibration.report`): self-contained, with the overlay
picture the CLI draws, the focal length and every warning; from what a calibration holds."""

from __future__ import annotations

import base64
import re
import struct

import numpy as np

import vpcal

PNG_PREFIX = "data:image/png;base64,"


def escape(text: str) -> str:
    """The report's HTML escaping."""
    for a, b in (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;"), ('"', "&quot;"), ("'", "&#39;")):
        text = text.replace(a, b)
    return text


def png_sizes(html: str):
    """(width, height) of every inlined PNG (its IHDR chunk)."""
    sizes = []
    for m in re.finditer(re.escape(PNG_PREFIX) + r'([A-Za-z0-9+/=]+)"', html):
        data = base64.b64decode(m.group(1), validate=True)
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
        sizes.append(struct.unpack(">II", data[16:24]))
    return sizes


def assert_offline(html: str) -> None:
    # The inlined images' base64 can spell anything of its alphabet.
    low = re.sub(r"base64,[A-Za-z0-9+/=]*", "base64,", html).lower()
    for bad in ("http://", "https://", "//cdn", "<script", "<link"):
        assert bad not in low, bad


def test_a_report_with_the_picture_and_tracks(scene, cli, tmp_path):
    cal = vpcal.calibrate(scene / "video.mp4", overlay=True, tracks=True, bootstrap=0)
    assert cal.overlay_png is not None and cal.overlay_png[:4] == b"\x89PNG"
    path = tmp_path / "report.html"
    html = cal.report(path)
    assert path.read_text(encoding="utf-8") == html
    assert html.startswith("<!DOCTYPE html>") and html.rstrip().endswith("</html>")
    assert_offline(html)
    assert png_sizes(html) == [cal.image_size]
    assert base64.b64encode(cal.overlay_png).decode() in html
    assert f"{cal.focal_px:.0f} px" in html and f"<code>{cal.focal_source}</code>" in html
    for w in cal.warnings:
        assert escape(w) in html, w
    assert "id=\"tracks\"" in html and f"{len(cal.tracks)} tracks" in html
    # The picture is the CLI's overlay, byte for byte.
    r = cli("calibrate", str(scene / "video.mp4"), "-o", str(tmp_path / "c.json"),
            "--overlay", str(tmp_path / "o.png"), "--report", str(tmp_path / "cli.html"),
            "--bootstrap", "0", "--quiet")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "o.png").read_bytes() == cal.overlay_png
    cli_html = (tmp_path / "cli.html").read_text(encoding="utf-8")
    assert png_sizes(cli_html) == [cal.image_size]
    assert f"{cal.focal_px:.0f} px" in cli_html


def test_a_loaded_calibration_reports_without_a_picture(scene, tmp_path):
    cal = vpcal.calibrate(scene / "video.mp4", bootstrap=0)
    cal.save(tmp_path / "c.json")
    html = vpcal.load(tmp_path / "c.json").report()
    assert_offline(html)
    assert png_sizes(html) == []
    assert "No picture" in html and "id=\"tracks\"" not in html
    assert f"{cal.focal_px:.0f} px" in html


def test_a_failed_run_reports_why():
    frames = np.zeros((10, 48, 64, 3), dtype=np.uint8)
    cal = vpcal.calibrate(frames, fps=25, raise_on_failure=False, overlay=True)
    assert not cal.ok
    html = cal.report()
    assert "Not calibrated" in html and escape(cal.reason) in html
    assert png_sizes(html) == [(64, 48)]
    assert_offline(html)
