#!/usr/bin/env python3
"""Write synthetic scenes in the KITTI vanishing-point truth format, so that `vpcal eval kitti`
measures the network and the per-vehicle edgelet VP2 on synthetic vehicles exactly as on the
real KITTI ones.

Usage: scripts/synth_kitti.py OUT STEP SCENE_DIR [SCENE_DIR ...]
  OUT        folder to write (vp_gt.json and image_2/)
  STEP       every STEP-th frame of each scene
  SCENE_DIR  a `vpcal synth scene|suite` scene (dataset/<name>/: video.mp4, camera.json,
             vehicles.jsonl)

Every moving vehicle of a kept frame becomes a KITTI vehicle: `occluded` 0 when at least 95 %
of it is visible, `truncated` 0 when its box lies inside the frame, its exact VP1/VP2 from
vehicles.jsonl. Then: `vpcal eval kitti --data OUT`. Needs ffmpeg.
"""
import json
import os
import subprocess
import sys


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out, step = sys.argv[1], int(sys.argv[2])
    os.makedirs(os.path.join(out, "image_2"), exist_ok=True)
    frames = {}
    for scene in sys.argv[3:]:
        name = os.path.basename(os.path.normpath(scene))
        cam = json.load(open(os.path.join(scene, "camera.json")))
        width, height = cam["width"], cam["height"]
        tmp = os.path.join(out, "tmp_" + name)
        os.makedirs(tmp, exist_ok=True)
        subprocess.run(
            ["ffmpeg", "-loglevel", "error", "-y", "-i", os.path.join(scene, "video.mp4"),
             "-vf", f"select='not(mod(n\\,{step}))'", "-vsync", "0",
             os.path.join(tmp, "%05d.png")],
            check=True)
        by_frame = {}
        for line in open(os.path.join(scene, "vehicles.jsonl")):
            v = json.loads(line)
            if not v["parked"] and v["frame"] % step == 0:
                by_frame.setdefault(v["frame"], []).append(v)
        for f, vehicles in sorted(by_frame.items()):
            src = os.path.join(tmp, "%05d.png" % (f // step + 1))
            if not os.path.exists(src):
                continue
            fid = "%s_%05d" % (name, f)
            os.replace(src, os.path.join(out, "image_2", fid + ".png"))
            items = []
            for v in vehicles:
                b = v["box"]
                inside = b[0] >= 1 and b[1] >= 1 and b[2] <= width - 1 and b[3] <= height - 1
                items.append({
                    "type": "Car",
                    "truncated": 0.0 if inside else 1.0,
                    "occluded": 0 if v["visible_fraction"] >= 0.95 else 1,
                    "box2d_label": v["box_clipped"],
                    "vp1_h": [*v["vp1"], 1.0],
                    "vp2_h": [*v["vp2"], 1.0],
                })
            frames[fid] = {"image": "image_2/" + fid + ".png", "pp": cam["pp"],
                           "fx": cam["focal_px"], "vehicles": items}
        for leftover in os.listdir(tmp):
            os.remove(os.path.join(tmp, leftover))
        os.rmdir(tmp)
    json.dump({"description": "synthetic scenes in the KITTI VP truth format", "frames": frames},
              open(os.path.join(out, "vp_gt.json"), "w"))
    print(len(frames), "frames,", sum(len(f["vehicles"]) for f in frames.values()), "vehicles")


if __name__ == "__main__":
    main()
