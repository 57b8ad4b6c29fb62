#!/usr/bin/env python3
"""Pickle fixtures and expected values for vpcal-formats' pickle reader tests.

Writes, under crates/vpcal-formats/tests/fixtures/pickle/:
  rich_py3_p{0..4}.pkl   one rich object pickled by Python 3's own pickler at protocols 0-4
                         (numpy 2 module paths, bytes through _codecs.encode at protocols 0-2)
  rich_py2_p{0,1,2}.pkl  the same object written the way Python 2 wrote BoxCars/BrnoCompSpeed
                         pickles: byte strings and ASCII text as STRING/BINSTRING/SHORT_BINSTRING,
                         numpy.core.multiarray and __builtin__ module paths
  edge_*.pkl             small hand-assembled pickles for edge cases (duplicate keys, 1 == 1.0,
                         text opcodes, escapes)
  *.canon                for each fixture, the canonical text of what Python's pickle.load
                         (encoding="latin1") returns; the Rust test prints the same text
and, when the BrnoCompSpeed data is present (VPCAL_DATA, default ../shared/data):
  gt_data_expected.json  per video: FNV-1a 64 digest of the canonical text of gt_data.pkl and a
                         few spot values, all computed by Python's pickle.

Canonical text (identical in tests/pickle.rs):
  None N | bool T/F | int i<decimal> | float f<16 hex digits of the IEEE-754 bits>
  str s<hex of UTF-8> | bytes b<hex> | list [a,b] | tuple (a,b) | dict {k:v,k:v} (insertion order)
  set set{...} / frozenset fset{...} with elements' canonical texts sorted
  numpy array nd<kind><itemsize or nothing for O>(shape,)[elements in C order]
  numpy scalar sc<kind><itemsize>[element]; array elements: floats as f..., ints i..., bools T/F.

Run with a Python that has numpy (e.g. python3 -m venv /tmp/v && /tmp/v/bin/pip install numpy):
  /tmp/v/bin/python scripts/pickle_fixtures.py
"""
import io
import json
import os
import pickle
import struct
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "crates", "vpcal-formats", "tests", "fixtures", "pickle")


# ----------------------------------------------------------------------------------------------
# canonical text


def canon_elem(x, kind):
    if kind == "f":
        return "f%016x" % struct.unpack(">Q", struct.pack(">d", float(x)))[0]
    if kind == "b":
        return "T" if bool(x) else "F"
    if kind in "iu":
        return "i%d" % int(x)
    return canon(x)


def canon(v):
    if v is None:
        return "N"
    if type(v) is bool:
        return "T" if v else "F"
    if isinstance(v, np.ndarray):
        kind = v.dtype.kind
        size = "" if kind == "O" else str(v.dtype.itemsize)
        shape = "(" + "".join("%d," % d for d in v.shape) + ")"
        flat = v.flatten(order="C")
        return "nd%s%s%s[%s]" % (kind, size, shape, ",".join(canon_elem(x, kind) for x in flat))
    if isinstance(v, np.generic):
        kind = v.dtype.kind
        return "sc%s%d[%s]" % (kind, v.dtype.itemsize, canon_elem(v, kind))
    if type(v) is int:
        return "i%d" % v
    if type(v) is float:
        return canon_elem(v, "f")
    if type(v) is str:
        return "s" + v.encode("utf-8").hex()
    if type(v) is bytes:
        return "b" + v.hex()
    if type(v) is list:
        return "[" + ",".join(canon(x) for x in v) + "]"
    if type(v) is tuple:
        return "(" + ",".join(canon(x) for x in v) + ")"
    if type(v) is dict:
        return "{" + ",".join(canon(k) + ":" + canon(x) for k, x in v.items()) + "}"
    if type(v) is set:
        return "set{" + ",".join(sorted(canon(x) for x in v)) + "}"
    if type(v) is frozenset:
        return "fset{" + ",".join(sorted(canon(x) for x in v)) + "}"
    raise TypeError("no canonical form for %r" % type(v))


def fnv1a64(text):
    h = 0xCBF29CE484222325
    for b in text.encode("utf-8"):
        h ^= b
        h = (h * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return "%016x" % h


# ----------------------------------------------------------------------------------------------
# a Python-2 style pickler


def py2_repr(b):
    """Python 2's repr() of a byte string, as protocol 0 STRING writes it."""
    quote = b'"' if (b"'" in b and b'"' not in b) else b"'"
    out = bytearray(quote)
    for c in b:
        ch = bytes([c])
        if ch == quote or ch == b"\\":
            out += b"\\" + ch
        elif ch == b"\t":
            out += b"\\t"
        elif ch == b"\n":
            out += b"\\n"
        elif ch == b"\r":
            out += b"\\r"
        elif c < 32 or c >= 127:
            out += b"\\x%02x" % c
        else:
            out += ch
    out += quote
    return bytes(out)


class Py2Pickler(pickle._Pickler):
    """Writes bytes and ASCII text as Python-2 `str` and names modules as Python 2 did."""

    dispatch = pickle._Pickler.dispatch.copy()

    def save_py2str(self, obj):
        if self.bin:
            n = len(obj)
            if n < 256:
                self.write(pickle.SHORT_BINSTRING + bytes([n]) + obj)
            else:
                self.write(pickle.BINSTRING + struct.pack("<i", n) + obj)
        else:
            self.write(pickle.STRING + py2_repr(obj) + b"\n")
        self.memoize(obj)

    def save_text(self, obj):
        try:
            data = obj.encode("ascii")
        except UnicodeEncodeError:
            return pickle._Pickler.save_str(self, obj)
        if self.bin:
            n = len(data)
            if n < 256:
                self.write(pickle.SHORT_BINSTRING + bytes([n]) + data)
            else:
                self.write(pickle.BINSTRING + struct.pack("<i", n) + data)
        else:
            self.write(pickle.STRING + py2_repr(data) + b"\n")
        self.memoize(obj)

    def save_global(self, obj, name=None):
        if name is None:
            name = getattr(obj, "__qualname__", None) or obj.__name__
        module = getattr(obj, "__module__", None) or pickle.whichmodule(obj, name)
        module = module.replace("numpy._core", "numpy.core")
        if module == "builtins":
            module = "__builtin__"
        self.write(pickle.GLOBAL + module.encode() + b"\n" + name.encode() + b"\n")
        self.memoize(obj)

    dispatch[bytes] = save_py2str
    dispatch[str] = save_text
    dispatch[type] = save_global


def dumps_py2(obj, protocol):
    buf = io.BytesIO()
    Py2Pickler(buf, protocol=protocol).dump(obj)
    return buf.getvalue()


# ----------------------------------------------------------------------------------------------
# fixtures


def rich():
    shared = [1, 2, 3]
    return {
        "none": None,
        "true": True,
        "false": False,
        "ints": [0, 1, -1, 255, 256, 65535, 65536, -(2**31), 2**31 - 1, 2**31, 2**63 - 1,
                 -(2**63), 2**63, -(2**63) - 1, 2**100, -(2**100), 12345678901234567890123],
        "floats": [0.0, -0.0, 1.5, -2.25, 1e300, 5e-324, float("inf"), float("-inf"),
                   float("nan"), 0.1],
        "str": "hello",
        "unicode": "\u017elu\u0165ou\u010dk\u00fd k\u016f\u0148 \u20ac \U0001F600",
        "escapes": "a\\b\n\r\x1a\x00'\"\t",
        "bytes": b"\x00\x01\xff\\\n'\"",
        "empty_bytes": b"",
        "long_bytes": bytes(range(256)) * 2,
        "tuple": (1, "a", (2.0, None)),
        "empty_tuple": (),
        "t1": (1,),
        "t2": (1, 2),
        "t3": (1, 2, 3),
        "set": {1, 2, 3},
        "frozenset": frozenset({"a", "b"}),
        "empty_set": set(),
        (1, "tuple-key"): "tuple key",
        42: "int key",
        -5: "negative int key",
        "nested": {"list": [[1, 2], [3, [4, [5]]]], "dict": {"a": {"b": {"c": 1}}}},
        "shared": [shared, shared],
        "arrays": {
            "f8": np.arange(6, dtype="<f8").reshape(2, 3) * 1.5,
            "f4": np.array([1.5, -2.0, 3.25], dtype="<f4"),
            "f8_be": np.array([1.0, 2.5, -0.125], dtype=">f8"),
            "f4_be": np.array([[1.0, 2.5], [3.0, 4.5]], dtype=">f4"),
            "i1": np.array([-128, 0, 127], dtype="i1"),
            "i2": np.array([-32768, 1, 32767], dtype="<i2"),
            "i4": np.array([-(2**31), 2, 2**31 - 1], dtype="<i4"),
            "i8": np.array([-(2**63), 3, 2**63 - 1], dtype="<i8"),
            "i4_be": np.array([-5, 6, 70000], dtype=">i4"),
            "u1": np.arange(256, dtype="u1"),
            "u2": np.array([0, 65535], dtype="<u2"),
            "u4": np.array([0, 2**32 - 1], dtype="<u4"),
            "u8": np.array([0, 2**64 - 1], dtype="<u8"),
            "u8_be": np.array([1, 2**40], dtype=">u8"),
            "b1": np.array([True, False, True]),
            "fortran": np.asfortranarray(np.arange(24, dtype="f8").reshape(2, 3, 4)),
            "fortran_i2": np.asfortranarray(np.arange(6, dtype="i2").reshape(2, 3)),
            "obj": np.array([1, "two", None, (3,)], dtype=object),
            "obj_fortran": np.asfortranarray(np.array([[1, "a"], [None, 2.5]], dtype=object)),
            "empty": np.zeros((0, 3)),
            "zero_d": np.array(7.5),
            "big": np.linspace(-1.0, 1.0, 300).reshape(3, 100),
        },
        "scalars": [np.float64(1.25), np.float32(-0.5), np.int64(-7), np.int32(42),
                    np.uint8(200), np.bool_(True), np.uint64(2**64 - 1), np.int16(-300)],
        "shared_array": [np.array([1.0, 2.0])] * 2,
    }


def edge_cases():
    """Hand-assembled pickles whose meaning Python decides (expected values come from
    pickle.loads)."""
    return {
        # duplicate keys: the first position, the last value
        "edge_dupkeys": b"\x80\x02}q\x00(U\x01aK\x01U\x01bK\x02U\x01aK\x03u.",
        # 1, 1.0 and True are one key; 2 and 2.0 one set element
        "edge_numeric_keys": b"\x80\x02}(K\x01U\x03intG?\xf0\x00\x00\x00\x00\x00\x00U\x05float\x88U\x04boolu.",
        "edge_set_dupes": b"\x80\x04\x8f(K\x02G@\x00\x00\x00\x00\x00\x00\x00K\x03\x90.",
        # protocol 0 text opcodes: INT bools, LONG, FLOAT, STRING escapes, UNICODE escapes,
        # DICT/LIST/TUPLE from marks, PUT/GET, POP, DUP, POP_MARK
        "edge_text": (b"(I01\nI00\nI-17\nL123456789012345678901234567890L\nF-1.25e-07\n"
                      b"S'tab\\there \\'q\\' \\x41\\101\\z\\n'\nS\"dq\\\"\"\nVa\\u20acb\\U0001f600\\\\u\n"
                      b"p0\n0g0\n2(I1\n1(lp1\nI5\naI6\na(dp2\nS'k'\np3\nI7\nsg3\ntp4\n."),
        # an empty MARK-built tuple and list, EMPTY_TUPLE, TUPLE1-3 and nesting
        "edge_tuples": b"\x80\x02(t](K\x01K\x02e)K\x01\x85K\x01K\x02\x86K\x01K\x02K\x03\x87\x87.",
        # protocol 4 with FRAME, MEMOIZE, STACK_GLOBAL, SHORT_BINBYTES, BINUNICODE8, BINBYTES8
        "edge_proto4": (b"\x80\x04\x95\x00\x00\x00\x00\x00\x00\x00\x00"
                        b"(C\x03abc\x94\x8d\x02\x00\x00\x00\x00\x00\x00\x00hi\x94"
                        b"\x8e\x01\x00\x00\x00\x00\x00\x00\x00z\x94"
                        b"\x8c\x08builtins\x94\x8c\tfrozenset\x94\x93](K\x01K\x02e\x85R"
                        b"h\x00t."),
        # LONG1/LONG4 with redundant sign bytes
        "edge_longs": b"\x80\x02(\x8a\x00\x8a\x02\xff\xff\x8a\x09\x00\x00\x00\x00\x00\x00\x00\x80\x00\x8b\x03\x00\x00\x00\x01\x00\x80t.",
    }


def write(name, data):
    with open(os.path.join(OUT, name + ".pkl"), "wb") as f:
        f.write(data)
    value = pickle.loads(data, encoding="latin1")
    with open(os.path.join(OUT, name + ".canon"), "w") as f:
        f.write(canon(value) + "\n")


def gt_expected(data_dir):
    base = os.path.join(data_dir, "bcs", "dataset")
    if not os.path.isdir(base):
        print("no BrnoCompSpeed data at %s: gt_data_expected.json not written" % base)
        return
    out = {}
    for session in sorted(os.listdir(base)):
        path = os.path.join(base, session, "gt_data.pkl")
        if not os.path.isfile(path):
            continue
        with open(path, "rb") as f:
            gt = pickle.load(f, encoding="latin1")
        dm = gt["distanceMeasurement"]
        cars = gt["cars"]
        out[session] = {
            "fnv1a64": fnv1a64(canon(gt)),
            "keys": list(gt.keys()),
            "fps": float(gt["fps"]),
            "distance_measurements": len(dm),
            "dm0_distance": float(dm[0]["distance"]),
            "dm0_p1": [float(x) for x in dm[0]["p1"]],
            "dm_last_p2": [float(x) for x in dm[-1]["p2"]],
            "dm_last_toVP1": bool(dm[-1]["toVP1"]),
            "cars": len(cars),
            "car0_speed": float(cars[0]["speed"]),
            "car0_lane_index": sorted(int(x) for x in cars[0]["laneIndex"]),
            "car_last_id": int(cars[-1]["carId"]),
            "valid_cars": sum(1 for c in cars if c["valid"]),
            "invalid_lanes": sorted(int(x) for x in gt["invalidLanes"]),
            "measurement_lines": len(gt["measurementLines"]),
            "lane_div_line0": [float(x) for x in gt["laneDivLines"][0]],
        }
    with open(os.path.join(OUT, "gt_data_expected.json"), "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")
    print("gt_data_expected.json: %d videos" % len(out))


def main():
    os.makedirs(OUT, exist_ok=True)
    obj = rich()
    for proto in range(5):
        write("rich_py3_p%d" % proto, pickle.dumps(obj, protocol=proto))
    for proto in range(3):
        write("rich_py2_p%d" % proto, dumps_py2(obj, proto))
    for name, data in edge_cases().items():
        write(name, data)
    data_dir = os.environ.get("VPCAL_DATA", os.path.join(ROOT, "..", "shared", "data"))
    gt_expected(data_dir)
    print("fixtures written to", OUT)


if __name__ == "__main__":
    sys.exit(main())
