#!/usr/bin/env python3
"""PyTorch peer of `vpcal bench-net`: the same stacked hourglass (DESIGN.md §5), on the CPU.

Prints one JSON object: parameter count, forward time for a batch of 10 crops (eval mode, no
autograd) and one training step for a batch of 8 (forward, MSE on all stacks, backward, Adam),
medians over `--runs` after `--warmup` untimed runs.

Usage: python scripts/bench_net.py [--threads N] [--forward-batch 10] [--train-batch 8]
Needs torch (e.g. a throwaway venv: python -m venv /work/venv-torch && pip install torch).
"""
import argparse
import json
import statistics
import time

import torch
from torch import nn
import torch.nn.functional as F


class Residual(nn.Module):
    """main = [1x1 C/2 ReLU BN] [3x3 C/2 ReLU BN] [1x1 C ReLU BN]; skip = id or 1x1+ReLU."""

    def __init__(self, cin, c, eps):
        super().__init__()
        h = c // 2
        self.conv1, self.bn1 = nn.Conv2d(cin, h, 1), nn.BatchNorm2d(h, eps=eps)
        self.conv2, self.bn2 = nn.Conv2d(h, h, 3, padding=1), nn.BatchNorm2d(h, eps=eps)
        self.conv3, self.bn3 = nn.Conv2d(h, c, 1), nn.BatchNorm2d(c, eps=eps)
        self.skip = nn.Conv2d(cin, c, 1) if cin != c else None

    def forward(self, x):
        s = F.relu(self.skip(x)) if self.skip is not None else x
        y = self.bn1(F.relu(self.conv1(x)))
        y = self.bn2(F.relu(self.conv2(y)))
        y = self.bn3(F.relu(self.conv3(y)))
        return s + y


class Hourglass(nn.Module):
    def __init__(self, c, depth, eps):
        super().__init__()
        blk = lambda: Residual(c, c, eps)  # noqa: E731
        self.down = nn.ModuleList(blk() for _ in range(depth))
        self.bottom_skip = blk()
        self.bottom = nn.ModuleList(blk() for _ in range(3))
        self.up_skip = nn.ModuleList(blk() for _ in range(depth - 1))
        self.up = nn.ModuleList(blk() for _ in range(depth - 1))

    def forward(self, x):
        left = []
        for i, b in enumerate(self.down):
            if i > 0:
                x = F.max_pool2d(x, 2)
            x = b(x)
            left.append(x)
        y = x
        for b in self.bottom:
            y = b(y)
        r = y + self.bottom_skip(x)
        for i, (sk, after) in enumerate(zip(self.up_skip, self.up)):
            f = left[len(left) - 2 - i]
            r = after(sk(f) + F.interpolate(r, scale_factor=2, mode="nearest"))
        return r


class StackedHourglass(nn.Module):
    def __init__(self, stacks=2, c=256, front=64, depth=4, outputs=8, pools=1, eps=1e-3):
        super().__init__()
        self.conv = nn.Conv2d(3, front, 7, padding=3)
        self.bn = nn.BatchNorm2d(front, eps=eps)
        self.res1, self.res2, self.res3 = (
            Residual(front, c // 2, eps),
            Residual(c // 2, c // 2, eps),
            Residual(c // 2, c, eps),
        )
        self.pools = pools
        self.hg = nn.ModuleList(Hourglass(c, depth, eps) for _ in range(stacks))
        self.head = nn.ModuleList(nn.Conv2d(c, c, 1) for _ in range(stacks))
        self.head_bn = nn.ModuleList(nn.BatchNorm2d(c, eps=eps) for _ in range(stacks))
        self.out = nn.ModuleList(nn.Conv2d(c, outputs, 1) for _ in range(stacks))
        self.next_head = nn.ModuleList(nn.Conv2d(c, c, 1) for _ in range(stacks - 1))
        self.next_out = nn.ModuleList(nn.Conv2d(outputs, c, 1) for _ in range(stacks - 1))

    def forward(self, x):
        x = self.bn(F.relu(self.conv(x)))
        x = self.res1(x)
        for _ in range(self.pools):
            x = F.max_pool2d(x, 2)
        x = self.res3(self.res2(x))
        outs = []
        for i, hg in enumerate(self.hg):
            h = self.head_bn[i](F.relu(self.head[i](hg(x))))
            o = self.out[i](h)
            outs.append(o)
            if i < len(self.next_head):
                x = self.next_head[i](h) + self.next_out[i](o) + x
        return outs


def keras_params(model):
    """Parameters plus batch-norm running statistics (how Keras and vpcal count)."""
    n = sum(p.numel() for p in model.parameters())
    n += sum(b.numel() for name, b in model.named_buffers() if not name.endswith("num_batches_tracked"))
    return n


def timed(fn, warmup, runs):
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(max(runs, 1)):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--forward-batch", type=int, default=10)
    ap.add_argument("--train-batch", type=int, default=8)
    ap.add_argument("--warmup", type=int, default=1)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--preset", choices=["paper", "tiny"], default="paper")
    a = ap.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    if a.preset == "paper":
        model, size, hm = StackedHourglass(), 128, 64
    else:
        model, size, hm = StackedHourglass(c=32, front=16, depth=3), 64, 32

    model.eval()
    x = torch.rand(a.forward_batch, 3, size, size)

    def fwd():
        with torch.no_grad():
            model(x)[-1].sum().item()

    f_runs = timed(fwd, a.warmup, a.runs)

    model.train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    xb = torch.rand(a.train_batch, 3, size, size)
    yb = torch.rand(a.train_batch, 8, hm, hm)

    def step():
        opt.zero_grad()
        loss = sum(F.mse_loss(o, yb) for o in model(xb))
        loss.backward()
        opt.step()
        loss.item()

    t_runs = timed(step, a.warmup, a.runs)
    f, t = statistics.median(f_runs), statistics.median(t_runs)
    print(json.dumps({
        "framework": f"torch {torch.__version__}",
        "threads": torch.get_num_threads(),
        "params": keras_params(model),
        "forward_batch": a.forward_batch,
        "forward_s": f,
        "forward_crops_per_s": a.forward_batch / f,
        "train_batch": a.train_batch,
        "train_step_s": t,
        "train_crops_per_s": a.train_batch / t,
        "forward_runs_s": f_runs,
        "train_runs_s": t_runs,
    }))


if __name__ == "__main__":
    main()
