#!/usr/bin/env python3
"""Extract the backbone (CSPDarknet: Focus stem, dark2..dark5) of the bundled YOLOX-nano ONNX
detector into a safetensors file for vpcal-net's burn encoder (`crates/vpcal-net/src/encoder.rs`),
and write golden feature-map statistics for its test.

Usage (from the repository root; needs numpy, onnx, onnxruntime):

    python3 scripts/convert_yolox_backbone.py

Reads   models/yolox_nano_coco/yolox_nano.onnx
Writes  models/encoders/yolox_nano_backbone.safetensors
        crates/vpcal-net/tests/data/yolox_nano_backbone_golden.json

Tensor names are the burn module's parameter paths (`dark3.csp.m.1.conv2.dconv.weight`),
f32 little-endian, shapes `[out, in / groups, kh, kw]` as in ONNX and burn. Batch norm is already
folded into the exported convolutions, so every convolution has a bias.

Golden input: one 1x3x128x128 float32 image in the detector's own convention (BGR, 0-255),
    x[c, h, w] = 127.5 + 127.5 * sin(0.07 * (c + 1) * h + 0.05 * (3 - c) * w + 0.3 * c)
For each backbone output (stem stride 2, dark2 stride 4, dark3 8, dark4 16, dark5 32) the JSON
holds its shape, mean, standard deviation (population) and 16 values at the flat indices
`k * (numel - 1) // 15`, k = 0..15, as computed by onnxruntime on the original graph cut after
the backbone.
"""
import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import numpy_helper

import safetensors_np

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "models/yolox_nano_coco/yolox_nano.onnx"
OUT = ROOT / "models/encoders/yolox_nano_backbone.safetensors"
GOLDEN = ROOT / "crates/vpcal-net/tests/data/yolox_nano_backbone_golden.json"
SIZE = 128

# Graph values at the end of each backbone stage (found by reading the graph: the Focus conv's
# SiLU output, and the SiLU outputs of each stage's last CSP conv3, which feed the PAFPN).
STAGE_OUTPUTS = {
    "stem": "input.7",
    "dark2": "input.67",
    "dark3": "input.175",
    "dark4": "input.283",
    "dark5": "input.359",
}


def dwconv(prefix):
    return [f"{prefix}.dconv", f"{prefix}.pconv"]


def csp(prefix, n):
    names = [f"{prefix}.conv1", f"{prefix}.conv2"]
    for i in range(n):
        names += [f"{prefix}.m.{i}.conv1"] + dwconv(f"{prefix}.m.{i}.conv2")
    return names + [f"{prefix}.conv3"]


def backbone_conv_names():
    """Burn paths of the backbone's convolutions in the order the ONNX graph runs them."""
    names = ["stem.conv"]
    for stage, n in (("dark2", 1), ("dark3", 3), ("dark4", 3)):
        names += dwconv(f"{stage}.down") + csp(f"{stage}.csp", n)
    names += dwconv("dark5.down") + ["dark5.spp.conv1", "dark5.spp.conv2"] + csp("dark5.csp", 1)
    return names


def golden_input():
    c, h, w = np.meshgrid(np.arange(3), np.arange(SIZE), np.arange(SIZE), indexing="ij")
    x = 127.5 + 127.5 * np.sin(0.07 * (c + 1) * h + 0.05 * (3 - c) * w + 0.3 * c)
    return x.astype(np.float32)[None]


def main():
    data = SRC.read_bytes()
    sha1 = hashlib.sha1(data).hexdigest()
    model = onnx.load_from_string(data)
    g = model.graph
    inits = {i.name: numpy_helper.to_array(i) for i in g.initializer}
    names = backbone_conv_names()
    convs = [n for n in g.node if n.op_type == "Conv"][: len(names)]
    # The last backbone conv must be the one producing dark5's output (through its SiLU).
    silu_of = {n.input[0]: n.output[0] for n in g.node if n.op_type == "Mul"}
    assert silu_of[convs[-1].output[0]] == STAGE_OUTPUTS["dark5"], "backbone end not where expected"
    tensors = {}
    for name, node in zip(names, convs):
        w, b = node.input[1], node.input[2]
        tensors[f"{name}.weight"] = inits[w]
        tensors[f"{name}.bias"] = inits[b]
    params = sum(t.size for t in tensors.values())
    meta = {
        "source": "models/yolox_nano_coco/yolox_nano.onnx",
        "source_sha1": sha1,
        "extracted": "YOLOX-nano backbone (Focus stem, dark2-dark5), BN folded",
        "script": "scripts/convert_yolox_backbone.py",
        "license": "Apache-2.0 (models/encoders/LICENSE)",
    }
    safetensors_np.write(OUT, tensors, meta)
    print(f"{OUT.relative_to(ROOT)}: {len(tensors)} tensors, {params} parameters, "
          f"sha256 {hashlib.sha256(OUT.read_bytes()).hexdigest()}")

    # Golden values: the graph cut after the backbone, with a free input size.
    cut = onnx.utils.Extractor(model).extract_model(["images"], list(STAGE_OUTPUTS.values()))
    for d, v in zip(cut.graph.input[0].type.tensor_type.shape.dim, ["n", None, "h", "w"]):
        if v:
            d.ClearField("dim_value")
            d.dim_param = v
    del cut.graph.value_info[:]  # shapes inferred for 416x416 input
    for o in cut.graph.output:
        o.type.tensor_type.ClearField("shape")
    opts = ort.SessionOptions()
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    sess = ort.InferenceSession(cut.SerializeToString(), opts, providers=["CPUExecutionProvider"])
    outs = sess.run(list(STAGE_OUTPUTS.values()), {"images": golden_input()})
    golden = {
        "source_sha1": sha1,
        "input": "1x3x128x128 BGR 0-255: x[c,h,w] = 127.5 + 127.5*sin(0.07*(c+1)*h + 0.05*(3-c)*w + 0.3*c)",
        "indices": "k * (numel - 1) // 15 for k in 0..16 (flat, row-major)",
        "features": {},
    }
    for (stage, _), a in zip(STAGE_OUTPUTS.items(), outs):
        a = a.astype(np.float64)
        flat = a.ravel()
        idx = [k * (flat.size - 1) // 15 for k in range(16)]
        golden["features"][stage] = {
            "shape": list(a.shape),
            "mean": float(flat.mean()),
            "std": float(flat.std()),
            "samples": [[i, float(flat[i])] for i in idx],
        }
        print(f"  {stage}: {list(a.shape)} mean {flat.mean():.5f} std {flat.std():.5f}")
    GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN.write_text(json.dumps(golden, indent=1) + "\n")
    print(f"{GOLDEN.relative_to(ROOT)} written")


if __name__ == "__main__":
    sys.exit(main())
