#!/usr/bin/env bash
# Calibrate every real clip in $VPCAL_DATA/traffic_video (default ../shared/data) with each
# detector and print, per clip and detector: exit status, boxes kept, vehicle tracks, the
# network's VP1 ray scatter (evidence.vp1_ray_scatter_deg), VP1 source, focal length, where
# the focal length came from (focal_source) and its 68 % interval, and the warnings.
# Outputs (calib.json, overlay.png) go to OUT/<clip>/<detector>/ for looking at.
#
# Usage: scripts/real_clips.sh OUT [DETECTORS...]   (default detectors: motion yolox)
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${1:?usage: scripts/real_clips.sh OUT [detectors...]}
shift
DETECTORS=${*:-motion yolox}
DATA=${VPCAL_DATA:-../shared/data}
VPCAL=${CARGO_TARGET_DIR:-target}/release/vpcal
printf '%-48s %-7s %4s %6s %6s %8s %-8s %9s %-9s %s\n' clip detector exit boxes tracks scatter vp1 focal source interval
for clip in "$DATA"/traffic_video/*; do
    [ -e "$clip" ] || continue
    case "$clip" in *.json) continue ;; esac
    name=$(basename "$clip")
    for det in $DETECTORS; do
        dir="$OUT/$name/$det"
        mkdir -p "$dir"
        "$VPCAL" calibrate "$clip" --detector "$det" --quiet -o "$dir/calib.json" \
            --overlay "$dir/overlay.png" > "$dir/stdout.txt" 2> "$dir/stderr.txt"
        code=$?
        python3 - "$dir/calib.json" "$name" "$det" "$code" <<'PY'
import json, sys
path, name, det, code = sys.argv[1:]
try:
    d = json.load(open(path))
except Exception:
    print(f"{name:<48} {det:<7} {code:>4} (no calibration file)")
    sys.exit()
e = d.get("evidence", {})
boxes = d.get("input", {}).get("vehicle_boxes")
tracks = e.get("track_lines", "-")
sc = e.get("vp1_ray_scatter_deg")
src = "tracks" if e.get("vp1_from_tracks") else ("edgelets" if e.get("vp1_from_edgelets") else ("network" if e else "-"))
f = d.get("focal_px")
fs = d.get("focal_source") or "-"
iv = d.get("focal_interval_px")
iv = f"{iv[0]:.0f}-{iv[1]:.0f}" if iv else "-"
print(f"{name:<48} {det:<7} {code:>4} {boxes!s:>6} {tracks!s:>6} {(f'{sc:.1f}' if sc is not None else '-'):>8} {src:<8} {(f'{f:.0f}' if f else '-'):>9} {fs:<9} {iv}")
for w in d.get("warnings", []):
    print(f"    warning: {w}")
PY
    done
done
