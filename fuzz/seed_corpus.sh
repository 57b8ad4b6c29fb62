#!/bin/sh
# Seed fuzz/corpus/pickle with the pickle fixtures and, when present, the real BrnoCompSpeed
# gt_data.pkl files (VPCAL_DATA, default ../shared/data). The corpus is not committed.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
data=${VPCAL_DATA:-$here/../../shared/data}
mkdir -p "$here/corpus/pickle"
cp "$here"/../crates/vpcal-formats/tests/fixtures/pickle/*.pkl "$here/corpus/pickle/"
if [ -d "$data/bcs/dataset" ]; then
    for d in "$data"/bcs/dataset/*/; do
        [ -f "$d/gt_data.pkl" ] && cp "$d/gt_data.pkl" "$here/corpus/pickle/gt_$(basename "$d").pkl"
    done
fi
ls "$here/corpus/pickle" | wc -l
