#!/usr/bin/env bash
# The plausibility table of issue 41: calibrate every real clip of the corpus
# ($VPCAL_DATA/traffic_corpus/clips) and of traffic_video with the default settings and
# --max-frames N (default 300), and print per clip: exit code, status, focal source, focal
# length and its 68 % interval, camera height, tilt, median track speed (and how many
# tracks have a speed), whether the road was called curved, lanes, and the failed
# plausibility checks. Outputs (calib.json, tracks.json, overlay.png, stderr) go to
# OUT/<clip>.* for looking at.
#
# Usage: scripts/plausibility_table.sh OUT [MAX_FRAMES] [CLIP...]
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${1:?usage: scripts/plausibility_table.sh OUT [MAX_FRAMES] [CLIP...]}
FRAMES=${2:-300}
shift $(( $# >= 2 ? 2 : 1 ))
DATA=${VPCAL_DATA:-../shared/data}
VPCAL=${VPCAL:-${CARGO_TARGET_DIR:-target}/release/vpcal}
mkdir -p "$OUT"
if [ $# -gt 0 ]; then
    CLIPS=("$@")
else
    CLIPS=("$DATA"/traffic_corpus/clips/* "$DATA"/traffic_video/*.avi "$DATA"/traffic_video/*.mp4)
fi
printf '%-40s %4s %-19s %-13s %6s %11s %6s %6s %8s %4s %-6s %5s %s\n' \
    clip exit status focal_source f interval h_m tilt v_kmh n curved lanes checks
for clip in "${CLIPS[@]}"; do
    [ -f "$clip" ] || continue
    name=$(basename "$clip"); name=${name%.*}
    "$VPCAL" calibrate "$clip" --max-frames "$FRAMES" --quiet -o "$OUT/$name.json" \
        --tracks "$OUT/$name.tracks.json" --overlay "$OUT/$name.png" \
        > "$OUT/$name.stdout" 2> "$OUT/$name.stderr"
    code=$?
    python3 - "$OUT/$name.json" "$OUT/$name.tracks.json" "$name" "$code" <<'PY'
import json, statistics, sys
path, tracks_path, name, code = sys.argv[1:]
def fmt(v, k=1):
    return "-" if v is None else f"{v:.{k}f}"
try:
    d = json.load(open(path))
except (OSError, ValueError):
    print(f"{name[:40]:40s} {code:>4s} (no calibration file)")
    sys.exit()
speeds, lanes = [], set()
try:
    for t in json.load(open(tracks_path))["tracks"]:
        if t["speed_kmh"] is not None:
            speeds.append(t["speed_kmh"])
        if t["lane"] is not None:
            lanes.add(t["lane"])
except (OSError, ValueError, KeyError):
    pass
iv = d.get("focal_interval_px") or [None, None]
checks = ",".join(c["check"] for c in d.get("failed_checks", []))
curved = (d.get("evidence") or {}).get("road_curved")
print(f"{name[:40]:40s} {code:>4s} {d['status']:19s} {str(d.get('focal_source')):13s} "
      f"{fmt(d.get('focal_px'), 0):>6s} {fmt(iv[0], 0):>5s}-{fmt(iv[1], 0):<5s} "
      f"{fmt(d.get('camera_height_m')):>6s} {fmt(d.get('tilt_deg')):>6s} "
      f"{fmt(statistics.median(speeds) if speeds else None):>8s} {len(speeds):4d} "
      f"{str(curved):6s} {len(lanes):5d} {checks}")
PY
done
