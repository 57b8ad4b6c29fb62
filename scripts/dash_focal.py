#!/usr/bin/env python3
"""Which focal length makes a road's lane marks come out right? A check of a calibration's
focal length on real footage with painted lane marks (a measurement, not part of vpcal).

The background (per-pixel median of every 10th frame, grey) is read along the dashed lane
line through the given pixels; dash centres are where it is brighter than its surroundings.
For focal lengths from 300 to 4,000 px (VP1, horizon angle and principal point from the
calibration file, as `vpcal calibrate -o` wrote them) it prints the median distance between
consecutive dash centres along the road divided by the lane width across it (the lane from
the dashed line to the neighbouring line at one row), next to the marking standard's ratio:
where they agree is the focal length the marks ask for. Needs numpy, scipy and ffmpeg.

Usage: python3 scripts/dash_focal.py VIDEO CALIB.json DASH_PTS LANE PERIOD_M LANE_M
  DASH_PTS: x,y pixel points on the dashed line, e.g. "130,230;143,215;197,150" (a quadratic
            in y is fitted through them)
  LANE:     x_dash,x_other,row: the two lane lines' x at one row
  PERIOD_M, LANE_M: the marking standard's dash period and lane width, metres
Example (bgslibrary_video03, US standard: 10 ft dash + 30 ft gap, 12 ft lanes):
  python3 scripts/dash_focal.py $VPCAL_DATA/traffic_video/bgslibrary_video03_cdnet_highway_320x240.avi \\
      calib.json "129,215;136,200;163,150" 129,252,215 12.19 3.66
"""
import json
import subprocess
import sys

import numpy as np

sys.path.insert(0, __file__.rsplit('/', 1)[0])
from shape_focal import camera, road  # noqa: E402


def background(video, w, h):
    raw = subprocess.run(['ffmpeg', '-loglevel', 'error', '-i', video, '-vf',
                          r'select=not(mod(n\,10))', '-vsync', '0', '-f', 'rawvideo',
                          '-pix_fmt', 'gray', '-'], capture_output=True, check=True).stdout
    return np.median(np.frombuffer(raw, np.uint8).reshape(-1, h, w), axis=0).astype(float)


def main():
    video, calib, pts, lane, period_m, lane_m = sys.argv[1:7]
    cal = json.load(open(calib))
    w, h = cal['image_size']
    bg = background(video, w, h)
    pts = np.array([[float(v) for v in p.split(',')] for p in pts.split(';')])
    xd, xo, row = (float(v) for v in lane.split(','))
    fit = np.polyfit(pts[:, 1], pts[:, 0], min(2, len(pts) - 1))
    prof = []
    for y in range(h - 1, int(pts[:, 1].min()) - 1, -1):
        xc = np.polyval(fit, y)
        xs = np.arange(int(xc) - 3, int(xc) + 4).clip(0, w - 1)
        around = bg[y, max(0, int(xc) - 12):int(xc) + 12]
        prof.append((y, xs[np.argmax(bg[y, xs])], bg[y, xs].max(), np.median(around)))
    prof = np.array(prof)
    on = prof[:, 2] > prof[:, 3] + 25
    centres, start = [], None
    for i, v in enumerate(on):
        if v and start is None:
            start = i
        if (not v or i == len(on) - 1) and start is not None:
            seg = prof[start:max(i, start + 1)]
            centres.append((seg[:, 1].mean() + 0.5, seg[:, 0].mean() + 0.5))
            start = None
    print('dash centres (x, y):', ', '.join(f'({x:.0f}, {y:.0f})' for x, y in centres))
    if len(centres) < 2:
        sys.exit('fewer than two dashes found along the given points')
    want = float(period_m) / float(lane_m)
    for f in [300, 441, 600, 800, 1000, 1200, 1400, 1700, 2000, 2500, 3000, 4000]:
        cam = camera(cal['pp'], cal['vp1'], cal['horizon']['angle_deg'], f)
        along = [road(cam, c)[0] for c in centres]
        period = np.median(np.abs(np.diff(along)))
        width = abs(road(cam, (xd + .5, row + .5))[1] - road(cam, (xo + .5, row + .5))[1])
        print(f'f {f:5d} px: dash period / lane width {period / width:.2f} (standard {want:.2f})')


if __name__ == '__main__':
    main()
