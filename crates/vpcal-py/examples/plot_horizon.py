"""Calibrate a real traffic clip and draw its horizon and a road grid with matplotlib.

    pip install ./crates/vpcal-py matplotlib tqdm
    python crates/vpcal-py/examples/plot_horizon.py            # writes horizon.png

The clip is read at run time from $VPCAL_DATA (default ../shared/data, beside the
repository): traffic_video/bgslibrary_video02_highway_cam_320x240.avi, a highway camera.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import vpcal  # noqa: E402

DATA = Path(os.environ.get("VPCAL_DATA", "../shared/data"))
CLIP = DATA / "traffic_video" / "bgslibrary_video02_highway_cam_320x240.avi"


def last_frame(video: Path, index: int) -> np.ndarray:
    """Frame `index` of the clip, as FFmpeg decodes it (RGB)."""
    r = subprocess.run(
        ["ffmpeg", "-nostdin", "-loglevel", "error", "-i", str(video), "-vf",
         f"select=eq(n\\,{index})", "-frames:v", "1", "-f", "rawvideo", "-pix_fmt", "rgb24",
         "pipe:1"],
        capture_output=True, check=True,
    )
    return np.frombuffer(r.stdout, dtype=np.uint8).reshape(240, 320, 3)


def main(out: str = "horizon.png") -> None:
    if not CLIP.is_file():
        sys.exit(f"{CLIP} is missing: set VPCAL_DATA to the folder that holds traffic_video/")
    # The motion detector suits this fixed camera; 200 frames (8 s) are enough.
    try:
        from tqdm.auto import tqdm  # noqa: F401

        progress = True
    except ImportError:
        progress = None
    cal = vpcal.calibrate(CLIP, detector="motion", max_frames=200, progress=progress)
    print(cal)
    print(f"focal length {cal.focal_px:.1f} px ({cal.focal_source}), "
          f"68% interval {cal.focal_interval_px[0]:.0f}-{cal.focal_interval_px[1]:.0f} px")
    print(f"horizon angle {cal.horizon_angle_deg:.2f} deg, VP1 {np.round(cal.vp1, 1)}")
    for w in cal.warnings:
        print("warning:", w)

    frame = last_frame(CLIP, 199)
    w, h = cal.image_size
    fig, ax = plt.subplots(figsize=(8, 6))
    ax.imshow(frame)
    xs = np.array([0.0, w])
    ax.plot(xs, cal.horizon_y(xs), color="yellow", lw=2, label="horizon")
    # A road grid (road units: no metric scale yet), lines along and across the road between
    # the road points under the bottom corners and the centre of the image.
    corners = cal.road_points([[0.0, h - 1.0], [w - 1.0, h - 1.0], [w / 2, h / 2]])
    x0, x1 = np.nanmin(corners[:, 0]), np.nanmax(corners[:, 0]) * 3
    y0, y1 = np.nanmin(corners[:, 1]), np.nanmax(corners[:, 1])
    for y in np.linspace(y0, y1, 7):
        line = cal.pixels(np.stack([np.linspace(x0, x1, 50), np.full(50, y)], axis=1))
        ax.plot(line[:, 0], line[:, 1], color="cyan", lw=0.8)
    for x in np.linspace(x0, x1, 9):
        line = cal.pixels(np.stack([np.full(50, x), np.linspace(y0, y1, 50)], axis=1))
        ax.plot(line[:, 0], line[:, 1], color="cyan", lw=0.8)
    ax.plot(*cal.vp1, "r+", ms=12, label="VP1")
    ax.set_xlim(0, w)
    ax.set_ylim(h, min(0, float(cal.vp1[1]) - 20))
    ax.set_title(f"f = {cal.focal_px:.0f} px ({cal.focal_source}), "
                 f"horizon {cal.horizon_angle_deg:.1f}°")
    ax.legend(loc="lower right")
    fig.savefig(out, dpi=100, bbox_inches="tight")
    print("wrote", out)


if __name__ == "__main__":
    main(*sys.argv[1:])
