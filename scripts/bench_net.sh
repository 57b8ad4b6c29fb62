#!/usr/bin/env bash
# Benchmark the VP network in vpcal (burn, flex CPU backend) against the same architecture in
# PyTorch, on the CPU, with the same thread count, in one run; prints crops/s and the ratios.
#
# Usage: scripts/bench_net.sh [PYTHON] [THREADS] [extra `vpcal bench-net` flags...]
#   PYTHON   interpreter with torch installed (default /work/venv-torch/bin/python; create one
#            with: python3 -m venv /work/venv-torch && /work/venv-torch/bin/pip install torch numpy)
#   THREADS  CPU threads for both (default: all cores)
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${1:-/work/venv-torch/bin/python}
THREADS=${2:-$(nproc)}
shift $(( $# > 2 ? 2 : $# ))
cargo build --release -p vpcal --bin vpcal
TARGET=${CARGO_TARGET_DIR:-target}
exec "$TARGET/release/vpcal" bench-net --torch "$PYTHON" --threads "$THREADS" "$@"
