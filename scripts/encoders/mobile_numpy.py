"""Forward passes of MobileNetV2 (tonylins layout) and EfficientNet-Lite0 (lukemelas layout) in
plain numpy: the reference for scripts/convert_mobile_encoders.py's golden values and classifier
check. Slow (float64, loops over kernel taps), written for clarity.
"""
import numpy as np

def conv2d(x, w, stride, pad, groups=1):
    # x [c,h,w], w [o, c/g, k, k], pad (top, bottom, left, right)
    t, b, l, r = pad
    x = np.pad(x, ((0, 0), (t, b), (l, r)))
    o, cg, k, _ = w.shape
    c, H, W = x.shape
    oh = (H - k) // stride + 1; ow = (W - k) // stride + 1
    out = np.zeros((o, oh, ow), np.float64)
    og = o // groups
    for g in range(groups):
        xs = x[g * cg:(g + 1) * cg]
        ws = w[g * og:(g + 1) * og]
        for dy in range(k):
            for dx in range(k):
                patch = xs[:, dy:dy + stride * (oh - 1) + 1:stride, dx:dx + stride * (ow - 1) + 1:stride]
                out[g * og:(g + 1) * og] += np.einsum('oc,chw->ohw', ws[:, :, dy, dx], patch)
    return out

def dwconv(x, w, stride, pad):
    t, b, l, r = pad
    x = np.pad(x, ((0, 0), (t, b), (l, r)))
    c, H, W = x.shape; k = w.shape[-1]
    oh = (H - k) // stride + 1; ow = (W - k) // stride + 1
    out = np.zeros((c, oh, ow))
    for dy in range(k):
        for dx in range(k):
            out += w[:, 0, dy, dx][:, None, None] * x[:, dy:dy + stride * (oh - 1) + 1:stride, dx:dx + stride * (ow - 1) + 1:stride]
    return out

def bn(x, d, p, eps):
    s = d[p + '.weight'] / np.sqrt(d[p + '.running_var'] + eps)
    return x * s[:, None, None] + (d[p + '.bias'] - d[p + '.running_mean'] * s)[:, None, None]

relu6 = lambda x: np.clip(x, 0, 6)

def same_pad(size, k, s):
    total = max((-(-size // s) - 1) * s + k - size, 0)
    return (total // 2, total - total // 2)

def sym(k):
    return (k // 2, k // 2, k // 2, k // 2)

MBV2 = [(1, 16, 1, 1), (6, 24, 2, 2), (6, 32, 3, 2), (6, 64, 4, 2), (6, 96, 3, 1), (6, 160, 3, 2), (6, 320, 1, 1)]
LITE0 = [(3, 1, 16, 1, 1), (3, 6, 24, 2, 2), (5, 6, 40, 2, 2), (3, 6, 80, 3, 2), (5, 6, 112, 3, 1), (5, 6, 192, 4, 2), (3, 6, 320, 1, 1)]

def mbv2(d, x):
    """x [3,S,S] normalised; returns list of every block output (index = features.i)."""
    eps = 1e-5
    x = relu6(bn(conv2d(x, d['features.0.0.weight'], 2, sym(3)), d, 'features.0.1', eps))
    outs = [x]; i = 1; cin = 32
    for t, c, n, s in MBV2:
        for j in range(n):
            st = s if j == 0 else 1
            p = f'features.{i}.conv'
            y = x
            if t == 1:
                y = relu6(bn(dwconv(y, d[p + '.0.weight'], st, sym(3)), d, p + '.1', eps))
                y = bn(conv2d(y, d[p + '.3.weight'], 1, sym(1)), d, p + '.4', eps)
            else:
                y = relu6(bn(conv2d(y, d[p + '.0.weight'], 1, sym(1)), d, p + '.1', eps))
                y = relu6(bn(dwconv(y, d[p + '.3.weight'], st, sym(3)), d, p + '.4', eps))
                y = bn(conv2d(y, d[p + '.6.weight'], 1, sym(1)), d, p + '.7', eps)
            x = x + y if (st == 1 and cin == c) else y
            cin = c; outs.append(x); i += 1
    x = relu6(bn(conv2d(x, d['features.18.0.weight'], 1, sym(1)), d, 'features.18.1', eps))
    outs.append(x)
    return outs

def lite0(d, x, classify=False):
    eps = 1e-3
    def tfpad(x, k, s):
        if s == 1:
            return sym(k)
        a = same_pad(x.shape[1], k, s); b = same_pad(x.shape[2], k, s)
        return (a[0], a[1], b[0], b[1])
    x = relu6(bn(conv2d(x, d['_conv_stem.weight'], 2, tfpad(x, 3, 2)), d, '_bn0', eps))
    outs = [x]; i = 0; cin = 32
    for k, t, c, n, s in LITE0:
        for j in range(n):
            st = s if j == 0 else 1
            p = f'_blocks.{i}'
            y = x
            if t != 1:
                y = relu6(bn(conv2d(y, d[p + '._expand_conv.weight'], 1, sym(1)), d, p + '._bn0', eps))
            y = relu6(bn(dwconv(y, d[p + '._depthwise_conv.weight'], st, tfpad(y, k, st)), d, p + '._bn1', eps))
            y = bn(conv2d(y, d[p + '._project_conv.weight'], 1, sym(1)), d, p + '._bn2', eps)
            x = x + y if (st == 1 and cin == c) else y
            cin = c; outs.append(x); i += 1
    if classify:
        x = relu6(bn(conv2d(x, d['_conv_head.weight'], 1, sym(1)), d, '_bn1', eps))
        v = x.mean(axis=(1, 2))
        return d['_fc.weight'] @ v + d['_fc.bias']
    return outs
