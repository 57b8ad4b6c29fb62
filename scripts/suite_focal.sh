#!/bin/bash
# Focal length per scene of the synthetic suite (true boxes, bootstrap 30) against the truth,
# with the focal source and whether the 68 % interval holds the truth. Renders the suite into
# SUITE_DIR (100 frames) when absent. VPCAL: the binary (default target/release/vpcal);
# VPCAL_EXTRA: more calibrate flags (e.g. `--no-edgelets` to see what the network's VP2 rays
# give without the edgelets).
V=${VPCAL:-target/release/vpcal}
S=${1:?usage: scripts/suite_focal.sh SUITE_DIR}
[ -d $S/dataset ] || nice $V synth suite -o $S --frames 100 --supersample 1 > $S.render.log 2>&1
for d in $S/dataset/*/; do n=$(basename $d)
  nice $V calibrate $d/video.mp4 --detections $d/detections.csv --quiet ${VPCAL_EXTRA:-} -o $S/$n.calib.json > /dev/null 2>&1
  python3 - "$d" "$S/$n.calib.json" <<'PY'
import json,sys
d,c=sys.argv[1],sys.argv[2]
t=json.load(open(d+'/camera.json'))['focal_px']
try: k=json.load(open(c))
except Exception as e: print(d.split('/')[-2],'no file'); sys.exit()
if k.get('status')!='calibrated': print(d.split('/')[-2],'refused:',(k.get('reason') or '')[:80]); sys.exit()
f=k['focal_px'];iv=k.get('focal_interval_px')
print(d.split('/')[-2], k['focal_source'], round(t,1), round(f,1), '%+.1f%%'%(100*(f/t-1)), iv and [round(x) for x in iv], iv and (iv[0]<=t<=iv[1]))
PY
done
