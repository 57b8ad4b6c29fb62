#!/usr/bin/env bash
# Calibrate every scene of the synthetic benchmark suite with the bundled model (or MODEL),
# once with the scenes' true vehicle boxes, once with the motion detector and once with the
# built-in learned detector (YOLOX-nano), then score all three against the scenes' ground
# truth with `vpcal eval bcs` (pure-calibration ratio error).
#
# Usage: scripts/eval_suite.sh SUITE_DIR [FRAMES] [extra `vpcal calibrate` flags...]
#   SUITE_DIR  rendered by `vpcal synth suite --out SUITE_DIR --frames FRAMES` if it does not exist
set -euo pipefail
cd "$(dirname "$0")/.."
SUITE=${1:?usage: scripts/eval_suite.sh SUITE_DIR [FRAMES] [calibrate flags...]}
FRAMES=${2:-150}
shift $(( $# > 2 ? 2 : $# ))
cargo build --release -p vpcal --bin vpcal
VPCAL=${CARGO_TARGET_DIR:-target}/release/vpcal
if [ ! -d "$SUITE/dataset" ]; then
    "$VPCAL" synth suite --out "$SUITE" --frames "$FRAMES"
fi
for scene in "$SUITE"/dataset/*/; do
    name=$(basename "$scene")
    res="$SUITE/results/$name"
    echo "== $name"
    mkdir -p "$res"
    # A scene that is not calibrated this time must not be scored with an older run's file.
    rm -f "$res/system_vpcal_trueboxes.json" "$res/system_vpcal_motion.json" "$res/system_vpcal_yolox.json"
    "$VPCAL" calibrate "$scene/video.mp4" --detections "$scene/detections.csv" --quiet \
        --bcs-json "$res/system_vpcal_trueboxes.json" "$@" 2>&1 | grep -E "focal length|NOT CALIBRATED" || true
    "$VPCAL" calibrate "$scene/video.mp4" --detector motion --quiet \
        --bcs-json "$res/system_vpcal_motion.json" "$@" 2>&1 | grep -E "focal length|NOT CALIBRATED" || true
    "$VPCAL" calibrate "$scene/video.mp4" --detector yolox --quiet \
        --bcs-json "$res/system_vpcal_yolox.json" "$@" 2>&1 | grep -E "focal length|NOT CALIBRATED" || true
done
"$VPCAL" eval bcs --dataset "$SUITE/dataset" --results "$SUITE/results" \
    --system groundtruth vpcal_trueboxes vpcal_motion vpcal_yolox
