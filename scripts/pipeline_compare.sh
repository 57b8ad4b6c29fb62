#!/bin/bash
# The calibration with a few crops per followed vehicle and one detector tile per frame
# (`--crops few --tile-rotation`) against every box through the network and every tile in
# every frame (`--crops all`, the default at 960 px wide and below): per clip, status, VP1
# shift, roll and focal length of both.
# usage: scripts/pipeline_compare.sh OUT CLIP...   (VPCAL: the binary; FRAMES: 300)
# Timings are not compared here (use `vpcal bench-pipeline` on a quiet machine).
set -uo pipefail
V=${VPCAL:-target/release/vpcal}
OUT=${1:?usage: OUT CLIP...}; shift
mkdir -p "$OUT"
for c in "$@"; do
  n=$(basename "$c"); n=${n%.*}
  "$V" calibrate "$c" --max-frames "${FRAMES:-300}" --quiet --crops few --tile-rotation -o "$OUT/$n.default.json" > "$OUT/$n.default.log" 2>&1
  "$V" calibrate "$c" --max-frames "${FRAMES:-300}" --quiet --crops all \
    -o "$OUT/$n.all.json" > "$OUT/$n.all.log" 2>&1
done
python3 - "$OUT" "$@" <<'PY'
import json, math, os, sys
out = sys.argv[1]
print("| clip | status all → few | VP1 shift (px, % of width) | roll all → few (°) | f all → few (px, source) |")
print("|---|---|---|---|---|")
for c in sys.argv[2:]:
    n = os.path.splitext(os.path.basename(c))[0]
    try:
        a = json.load(open(f"{out}/{n}.all.json")); b = json.load(open(f"{out}/{n}.default.json"))
    except (OSError, ValueError):
        print(f"| {n} | no calibration file | | | |"); continue
    row = [n, f"{a['status']} → {b['status']}"]
    if a.get("vp1") and b.get("vp1"):
        d = math.dist(a["vp1"], b["vp1"]); w = a["image_size"][0]
        row += [f"{d:.1f} ({100 * d / w:.1f} %)", f"{a['roll_deg']:.2f} → {b['roll_deg']:.2f}",
                f"{a['focal_px']:.0f} ({a['focal_source']}) → {b['focal_px']:.0f} ({b['focal_source']})"]
    else:
        row += ["-", "-", "-"]
    print("| " + " | ".join(row) + " |")
PY
