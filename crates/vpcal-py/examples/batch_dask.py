"""Calibrate many cameras in parallel on Dask: one worker process per core.

    pip install ./crates/vpcal-py "dask[distributed]"
    python crates/vpcal-py/examples/batch_dask.py ../shared/data/traffic_video/*.avi

Each camera is one vpcal.calibrate call; vpcal.batch.calibrate_many sends them to a Dask
LocalCluster (or to the cluster of a Client you pass) and collects one BatchResult per camera:
its calibration, or why it has none. A camera that fails does not stop the others.
"""

from __future__ import annotations

import sys

import vpcal
from vpcal.batch import calibrate_many


def main(paths: list[str]) -> None:
    if not paths:
        sys.exit("usage: batch_dask.py VIDEO...")
    options = vpcal.Options(detector="motion", max_frames=200)
    results = calibrate_many(
        paths, options, on_result=lambda r: print("done:", r.source, file=sys.stderr)
    )
    for r in results:
        if r.ok:
            c = r.calibration
            print(f"{r.source}: f = {c.focal_px:.0f} px ({c.focal_source}), "
                  f"horizon {c.horizon_angle_deg:.2f}°")
            c.save(r.source + ".calib.json")
        else:
            print(f"{r.source}: {'no calibration' if r.not_calibrated else 'error'}: {r.error}")


if __name__ == "__main__":
    main(sys.argv[1:])
