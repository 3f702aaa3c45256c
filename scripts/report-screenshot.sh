#!/usr/bin/env bash
# Renders an HTML report in headless Chromium and checks the PNG is not
# blank. Usage: scripts/report-screenshot.sh REPORT.html OUT.png [WIDTHxHEIGHT]
# (default 1400x3000). Needs Debian's chromium (apt-get install chromium).
set -euo pipefail
html=${1:?usage: $0 REPORT.html OUT.png [WIDTHxHEIGHT]}
png=${2:?usage: $0 REPORT.html OUT.png [WIDTHxHEIGHT]}
size=${3:-1400x3000}
browser=$(command -v chromium || command -v chromium-browser || true)
[ -n "$browser" ] || { echo "chromium not found (apt-get install -y chromium)" >&2; exit 1; }
[ -f "$html" ] || { echo "$html: no such file" >&2; exit 1; }
profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT
rm -f "$png"
# No network at all: the report must open offline.
timeout 120 "$browser" --headless --no-sandbox --disable-gpu --disable-quic \
    --no-first-run --disable-background-networking --disable-component-update \
    --disable-sync --hide-scrollbars --user-data-dir="$profile" \
    --proxy-server=127.0.0.1:9 --screenshot="$png" --window-size="${size/x/,}" \
    "file://$(realpath "$html")" >/dev/null 2>&1 || true
[ -s "$png" ] || { echo "$png: no screenshot written" >&2; exit 1; }
# Not blank: a PNG of plots and tables is far larger than a white page,
# and its pixels are not all one colour (python3 is optional).
bytes=$(stat -c %s "$png")
[ "$bytes" -gt 50000 ] || { echo "$png: only $bytes bytes, looks blank" >&2; exit 1; }
if command -v python3 >/dev/null; then
python3 - "$png" <<'PY'
import struct, sys, zlib
data = open(sys.argv[1], "rb").read()
assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
pos, idat, w = 8, b"", 0
while pos < len(data):
    n, kind = struct.unpack(">I4s", data[pos:pos + 8])
    body = data[pos + 8:pos + 8 + n]
    if kind == b"IHDR":
        w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
    elif kind == b"IDAT":
        idat += body
    pos += 12 + n
raw = zlib.decompress(idat)
bpp = {2: 3, 6: 4}.get(ctype, 1) * depth // 8
stride = 1 + w * bpp
# Filter bytes aside, count rows that hold anything but their first byte
# repeated (filtered rows of a flat colour are constant after filtering).
busy = sum(1 for r in range(h) if len(set(raw[r * stride + 1:(r + 1) * stride])) > 2)
print(f"{sys.argv[1]}: {w}x{h}, {len(data)} bytes, {busy} of {h} rows with content")
assert busy > h // 5, "mostly blank"
PY
fi
echo "ok: $png"
