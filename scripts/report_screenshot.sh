#!/usr/bin/env bash
# Render an HTML report of `vpcal calibrate --report` to a PNG with headless Chromium, to look
# at it the way a reader sees it (and to check that it needs no network).
#
#   scripts/report_screenshot.sh REPORT.html OUT.png [WIDTH,HEIGHT]
#
# Chromium: /usr/bin/chromium (Debian's `chromium` package; installed with apt-get when
# missing and running as root), or $CHROMIUM. The window is 1280x3000 unless given.
set -euo pipefail

if [[ $# -lt 2 || $# -gt 3 ]]; then
    echo "usage: $0 REPORT.html OUT.png [WIDTH,HEIGHT]" >&2
    exit 2
fi
report=$1
out=$2
size=${3:-1280,3000}
if [[ ! -f $report ]]; then
    echo "$0: $report: no such file" >&2
    exit 1
fi

chromium=${CHROMIUM:-/usr/bin/chromium}
if [[ ! -x $chromium ]]; then
    if [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null; then
        echo "$0: installing chromium (apt-get)" >&2
        apt-get update -qq >/dev/null
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
    else
        echo "$0: $chromium not found: install Debian's chromium package or set CHROMIUM" >&2
        exit 1
    fi
fi

profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT
# Absolute paths: Chromium resolves them against its own working directory otherwise.
abs_report=$(cd "$(dirname "$report")" && pwd)/$(basename "$report")
mkdir -p "$(dirname "$out")"
abs_out=$(cd "$(dirname "$out")" && pwd)/$(basename "$out")

"$chromium" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync \
    --hide-scrollbars --user-data-dir="$profile" \
    --screenshot="$abs_out" --window-size="$size" \
    "file://$abs_report" 2> >(grep -v -e 'dbus' -e 'Fontconfig' >&2 || true)

if [[ ! -s $abs_out ]]; then
    echo "$0: chromium wrote no screenshot" >&2
    exit 1
fi
echo "$abs_out"
