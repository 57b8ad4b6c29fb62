"""Read and write safetensors files of f32 tensors with numpy only (the scripts' shared I/O).

write(path, tensors, metadata): tensors sorted by name, f32 little-endian, header padded to 8
bytes, written to a temporary file beside `path` and renamed over it.
read(path) -> (tensors, metadata): every tensor must be F32.
"""
import json
import struct
import sys

import numpy as np


def write(path, tensors, metadata):
    header = {"__metadata__": metadata}
    offset = 0
    blobs = []
    for name in sorted(tensors):
        a = np.ascontiguousarray(tensors[name], dtype="<f4")
        b = a.tobytes()
        header[name] = {"dtype": "F32", "shape": list(a.shape), "data_offsets": [offset, offset + len(b)]}
        offset += len(b)
        blobs.append(b)
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * ((8 - len(h) % 8) % 8)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(h)))
        f.write(h)
        for b in blobs:
            f.write(b)
    tmp.replace(path)


def read(path):
    data = path.read_bytes()
    n = struct.unpack("<Q", data[:8])[0]
    header = json.loads(data[8:8 + n])
    meta = header.pop("__metadata__", {})
    base = 8 + n
    tensors = {}
    for name, h in header.items():
        if h["dtype"] != "F32":
            sys.exit(f"{path}: tensor {name} has dtype {h['dtype']}, expected F32")
        a, b = h["data_offsets"]
        tensors[name] = np.frombuffer(data[base + a:base + b], dtype="<f4").reshape(h["shape"])
    return tensors, meta
