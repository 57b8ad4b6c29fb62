#!/usr/bin/env python3
"""Average the weights of several checkpoints of one `vpcal train` run (numpy only).

Usage:
    python3 scripts/average_checkpoints.py -o OUT.safetensors CKPT [CKPT ...]

Each CKPT is a checkpoint's model.safetensors or its folder (RUN/checkpoints/epoch-0018). All
must hold the same tensors (names, shapes, f32); the output holds their element-wise mean
(batch-norm running statistics included) and the first file's metadata (the model config,
kind and parameter ids), so `vpcal ... --model OUT.safetensors` loads it like any checkpoint.

Why: late in a constant-rate run the held-out real-camera errors move by 1-3 degrees from one
epoch to the next (docs/network.md); the mean of the last few epochs' weights is one model
that does not depend on where the run was stopped.
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

import safetensors_np


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-o", "--out", type=Path, required=True)
    ap.add_argument("checkpoints", type=Path, nargs="+")
    a = ap.parse_args()
    paths = [p / "model.safetensors" if p.is_dir() else p for p in a.checkpoints]
    first, meta = safetensors_np.read(paths[0])
    acc = {k: v.astype(np.float64) for k, v in first.items()}
    for p in paths[1:]:
        t, _ = safetensors_np.read(p)
        if set(t) != set(acc):
            sys.exit(f"{p}: tensors differ from {paths[0]}: "
                     f"{sorted(set(t) ^ set(acc))[:5]}")
        for k, v in t.items():
            if v.shape != acc[k].shape:
                sys.exit(f"{p}: tensor {k} has shape {list(v.shape)}, {paths[0]} {list(acc[k].shape)}")
            acc[k] += v
    out = {k: (v / len(paths)).astype(np.float32) for k, v in acc.items()}
    meta = dict(meta)
    meta["vpcal.averaged_from"] = json.dumps([str(p) for p in paths])
    safetensors_np.write(a.out, out, meta)
    print(f"{a.out}: mean of {len(paths)} checkpoints, {len(out)} tensors")


if __name__ == "__main__":
    main()
