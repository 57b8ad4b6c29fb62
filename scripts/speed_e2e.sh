#!/bin/bash
# End-to-end speeds on synthetic scenes: video -> vpcal calibrate (a detector, a taped or the
# automatic scale) -> tracks -> `vpcal eval speed` against the scene's true speeds.
# usage: scripts/speed_e2e.sh OUT DETECTOR SCALE SCENE_ROOT...
#   DETECTOR: motion | yolox | true (the scene's true boxes, detections.csv)
#   SCALE: taped (the scene's first taped distance) | auto (the vehicles' sizes)
#   SCENE_ROOT: a `vpcal synth scene -o` folder (dataset/<name>/ and results/<name>/)
# VPCAL: the binary (default target/release/vpcal). Prints eval speed's tables (system_vpcal and
# system_groundtruth: the true boxes' tracks with the true camera, the protocol's floor).
set -euo pipefail
V=${VPCAL:-target/release/vpcal}
OUT=${1:?usage: OUT DETECTOR SCALE SCENE_ROOT...}; DET=$2; SCALE=$3; shift 3
mkdir -p "$OUT"
for root in "$@"; do
  for d in "$root"/dataset/*/; do
    n=$(basename "$d")
    mkdir -p "$OUT/dataset" "$OUT/results/$n"
    ln -sfn "$(realpath "$d")" "$OUT/dataset/$n"
    read -r -a args <<< "${VPCAL_EXTRA:-}"
    if [ "$DET" = true ]; then args+=(--detections "$d/detections.csv"); else args+=(--detector "$DET"); fi
    if [ "$SCALE" = taped ]; then
      read -r pts dist < <(python3 -c "import json,sys;m=json.load(open(sys.argv[1]))['distanceMeasurement'][0];print(','.join('%.3f'%v for v in m['p1'][:2]+m['p2'][:2]), m['distance'])" "$d/gt_data.json")
      args+=(--scale-points "$pts" --scale-distance "$dist")
    fi
    size=$(python3 -c "import json,sys;c=json.load(open(sys.argv[1]));print('%dx%d'%(c['width'],c['height']))" "$d/camera.json")
    "$V" calibrate "$d/video.mp4" "${args[@]}" --quiet -o "$OUT/$n.calib.json" \
      --tracks "$OUT/$n.tracks.json" --bcs-json "$OUT/results/$n/system_vpcal.json" > "$OUT/$n.log" 2>&1 \
      || { echo "$n: calibrate failed: $(tail -1 "$OUT/$n.log")"; continue; }
    cp "$root/results/$n/system_groundtruth.json" "$OUT/results/$n/" 2>/dev/null || true
    echo "$n ($DET, $SCALE scale): $(grep -E '^ *(tracks|scale) ' "$OUT/$n.log" | sed 's/  */ /g' | tr '\n' ';')"
  done
done
# One evaluation over every scene (they share the image size of the last one).
"$V" eval speed --dataset "$OUT/dataset" --results "$OUT/results" --image-size "$size"
