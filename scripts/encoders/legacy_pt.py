"""Reader of PyTorch's legacy (pre-1.6, non-zip) serialisation, numpy only."""
import pickle, struct, collections
import numpy as np

DT = {"FloatStorage": np.float32, "LongStorage": np.int64, "IntStorage": np.int32,
      "DoubleStorage": np.float64, "HalfStorage": np.float16, "ByteStorage": np.uint8}

class _Storage:
    def __init__(self, kind): self.kind = kind

def _rebuild(storage, offset, size, stride, *rest):
    return ("tensor", storage, offset, tuple(size), tuple(stride))

class _U(pickle.Unpickler):
    def __init__(self, f, storages):
        super().__init__(f); self.storages = storages
    def find_class(self, module, name):
        if module == "torch._utils" and name in ("_rebuild_tensor_v2", "_rebuild_tensor"):
            return _rebuild
        if module == "torch" and name.endswith("Storage"):
            return _Storage(name)
        if module == "collections" and name == "OrderedDict":
            return collections.OrderedDict
        raise pickle.UnpicklingError(f"unexpected class {module}.{name}")
    def persistent_load(self, pid):
        typename, kind, key, location, size = pid[:5]
        assert typename == "storage"
        self.storages[key] = (kind.kind, size)
        return key

def load(path):
    with open(path, "rb") as f:
        for _ in range(3):  # magic number, protocol version, system info
            pickle.load(f)
        storages = {}
        obj = _U(f, storages).load()
        keys = pickle.load(f)
        f.read(0)
        data = {}
        for k in keys:
            n = struct.unpack("<q", f.read(8))[0]
            dt = DT[storages[k][0]]
            data[k] = np.frombuffer(f.read(n * np.dtype(dt).itemsize), dtype=dt)
    out = collections.OrderedDict()
    for name, t in obj.items():
        _, key, off, size, stride = t
        buf = data[key]
        arr = np.lib.stride_tricks.as_strided(buf[off:], shape=size,
                                              strides=[s * buf.itemsize for s in stride])
        out[name] = np.array(arr)
    return out
