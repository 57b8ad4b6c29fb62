#!/usr/bin/env python3
"""Detector boxes of a rendered scene against its true vehicles, per rendered kind.

For each box of a run's per-vehicle records (`vpcal calibrate --vehicles`) matched (IoU >= 0.6)
to a fully visible true vehicle of the same frame (`vehicles.jsonl` of `vpcal synth scene`),
away from the frame's edge, prints the median ratio of its width and height to the box of the
vehicle's cuboid and to the box of its car outline (body to 0.65 of the height, roof 0.45 of
the length and 0.75 of the width: `vehicle_scale::PASSENGER_CAR_CABIN`), both projected with
the scene's true camera, and the vehicles' median dimensions.

usage: scripts/synth_box_check.py SCENE_DIR RECORDS   (needs numpy)
"""
import json, sys, math, collections
import numpy as np
d, vj = sys.argv[1], sys.argv[2]
cam = json.load(open(d + '/camera.json'))
K = np.array(cam['K']); R = np.array(cam['R']); C = np.array(cam['position_m'])
W, H = cam['width'], cam['height']
def proj(p):
    q = K @ (R @ (np.asarray(p) - C)); return q[:2] / q[2]
def outline_box(pose, dims, cabin=True):
    L, Wd, Hh = dims; s, c = math.sin(pose['heading']), math.cos(pose['heading'])
    parts = [(1, 1, [0, 0.65 if cabin else 1.0])] + ([(0.45, 0.75, [1.0])] if cabin else [])
    pts = []
    for lf, wf, zs in parts:
        for a in (-.5, .5):
            for w in (-.5, .5):
                dx, dy = a * lf * L, w * wf * Wd
                x = pose['x'] + dx * c - dy * s; y = pose['y'] + dx * s + dy * c
                for z in zs: pts.append(proj([x, y, z * Hh]))
    pts = np.array(pts); return [*pts.min(0), *pts.max(0)]
truth = collections.defaultdict(list)
for l in open(d + '/vehicles.jsonl'):
    v = json.loads(l); truth[v['frame']].append(v)
recs = json.load(open(vj))
recs = recs['vehicles'] if isinstance(recs, dict) else recs
def iou(a, b):
    ix = max(0, min(a[2], b[2]) - max(a[0], b[0])); iy = max(0, min(a[3], b[3]) - max(a[1], b[1]))
    i = ix * iy; u = (a[2]-a[0])*(a[3]-a[1]) + (b[2]-b[0])*(b[3]-b[1]) - i
    return i / u if u > 0 else 0
rows = []
for r in recs:
    fr = r.get('frame_cnt', r.get('frame'))
    b = r['box']
    if max(b) <= 1.5: b = [b[1]*W, b[0]*H, b[3]*W, b[2]*H]  # normalised ymin,xmin,ymax,xmax
    best = max(truth.get(int(round(fr)), []), key=lambda v: iou(b, v['box']), default=None)
    if best is None or iou(b, best['box']) < 0.6: continue
    if best['visible_fraction'] < 0.99 or best['box'] != best['box_clipped']: continue
    if min(b[0], b[1]) < 10 or b[2] > W - 10 or b[3] > H - 10: continue
    cb = best['box']; ob = outline_box(best['pose'], best['dims_m'])
    cb2 = outline_box(best['pose'], best['dims_m'], cabin=False)
    rows.append((best['kind'], best['id'], b[2]-b[0], b[3]-b[1], cb[2]-cb[0], cb[3]-cb[1], ob[2]-ob[0], ob[3]-ob[1], cb2[2]-cb2[0], cb2[3]-cb2[1], best['dims_m']))
print('matched boxes', len(rows), 'check cuboid proj vs bb3d box (w,h ratio med):',
      np.median([r[8]/r[4] for r in rows]), np.median([r[9]/r[5] for r in rows]))
bykind = collections.defaultdict(list)
for r in rows: bykind[r[0]].append(r)
print('%-10s %5s %5s | det/cuboid w h | det/outline w h | outline/cuboid h | dims med' % ('kind','boxes','veh'))
for k, rs in sorted(bykind.items(), key=lambda kv: -len(kv[1])):
    a = np.array([r[2:10] for r in rs])
    print('%-10s %5d %5d | %.3f %.3f | %.3f %.3f | %.3f | %s' % (k, len(rs), len({r[1] for r in rs}),
        np.median(a[:,0]/a[:,2]), np.median(a[:,1]/a[:,3]), np.median(a[:,0]/a[:,4]), np.median(a[:,1]/a[:,5]),
        np.median(a[:,5]/a[:,3]), np.round(np.median([r[10] for r in rs], 0), 2)))
a = np.array([r[2:10] for r in rows])
print('all        det/cuboid %.3f %.3f det/outline %.3f %.3f' % (np.median(a[:,0]/a[:,2]), np.median(a[:,1]/a[:,3]), np.median(a[:,0]/a[:,4]), np.median(a[:,1]/a[:,5])))
