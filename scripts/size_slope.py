#!/usr/bin/env python3
"""Do vehicle sizes grow away from the horizon as they should? For each real BrnoCompSpeed dev
video: the reference detector's boxes (detections.json, score >= 0.5) against the horizon of
the reference camera (camera_truth.json); prints the Theil-Sen slope of ln sqrt(w h) against
ln(distance of the box's bottom centre below the horizon), the boxes used, and the 10-90 %
range of ln distance. A correct horizon gives a slope near 1; vpcal-geom's aggregate::sizes
keeps MIN_SIZE_SLOPE with these numbers. Needs numpy. Usage: scripts/size_slope.py [DATA]
"""
import sys
import json, math, glob, os, numpy as np
D=(sys.argv[1] if len(sys.argv) > 1 else '../shared/data') + '/bcs'
truth=json.load(open(f'{D}/camera_truth.json'))['cameras']
def slope(boxes, vp1, vp2, W, H):
    # horizon line through vp1, vp2; d = distance of bottom centre below it
    a=np.cross([*vp1,1.0],[*vp2,1.0]); a=a/np.hypot(a[0],a[1])
    # orient so that image centre bottom is positive
    if a@[W/2,H,1]<0: a=-a
    xs=[];ys=[]
    for x0,y0,x1,y1 in boxes:
        if x0<10 or y0<10 or x1>W-10 or y1>H-10: continue
        d=a@[(x0+x1)/2,y1,1]; s=math.sqrt((x1-x0)*(y1-y0))
        if d<=0: continue
        xs.append(math.log(d)); ys.append(math.log(s))
    xs=np.array(xs); ys=np.array(ys)
    if len(xs)<20: return None
    # Theil-Sen on a subsample
    rng=np.random.default_rng(0); i=rng.integers(0,len(xs),4000); j=rng.integers(0,len(xs),4000)
    m=np.abs(xs[i]-xs[j])>0.05
    sl=np.median((ys[i]-ys[j])[m]/(xs[i]-xs[j])[m])
    return sl, len(xs), np.percentile(xs,90)-np.percentile(xs,10)
for v in sorted(truth):
    t=truth[v]
    dets=json.load(open(f'{D}/dataset/{v}/detections.json'))
    boxes=[]
    for f in dets:
        for b,s in zip(f['boxes'],f['scores']):
            if s<0.5: continue
            ymin,xmin,ymax,xmax=b; boxes.append((xmin*1920,ymin*1080,xmax*1920,ymax*1080))
    r = slope(boxes,t['vp1'],t['vp2'],1920,1080)
    print(f'{v:<16} slope {r[0]:.2f}  boxes {r[1]:>5}  ln-distance range {r[2]:.2f}')
