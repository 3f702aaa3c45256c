#!/usr/bin/env bash
# The time-offset state on the shared simulated drive: GNSS time tags
# shifted by +5, +20, +50, +100 and −50 ms (the drive starts moving at
# +60 s), fused with `--estimate-time-offset`, against the synchronized
# case. Usage: docs/offset/run_offsets.sh [extra fuse options]
# (after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/../.."
B=$(pwd)/${NAVSYNC:-target/release/navsync}
D=${DATA:-$(pwd)/../shared/data/sim-drive-adis16465}
out=$(mktemp -d)
sed "s#\./imu.txt#$D/imu.txt#; s#\./gnss.txt#$D/gnss.txt#" "$D/kf-gins.yaml" > "$out/cfg0.yaml"
$B fuse --config "$out/cfg0.yaml" --output "$out/sync" > /dev/null 2>&1
$B eval --truth "$D/truth.nav" --nav "$out/sync/navresult.nav" --json "$out/sync.json" > /dev/null
printf '| GNSS tag shift (ms) | error 60 s after the start of driving (ms) | final estimate (ms) | final error (ms) | final σ (ms) | max |error|/σ after 60 s of driving | horiz. RMS (m) | / synchronized | KF-GINS-class filter without the state, horiz. RMS (m) |\n|---|---|---|---|---|---|---|---|---|\n'
for ms in 5 20 50 100 -50; do
  awk -v s="$ms" '{ if ($0 ~ /^#/ || NF == 0) print; else { $1 = sprintf("%.9f", $1 + s / 1000.0); print } }' "$D/gnss.txt" > "$out/gnss$ms.txt"
  sed "s#\./imu.txt#$D/imu.txt#; s#\./gnss.txt#$out/gnss$ms.txt#" "$D/kf-gins.yaml" > "$out/cfg$ms.yaml"
  $B fuse --config "$out/cfg$ms.yaml" --output "$out/o$ms" --estimate-time-offset "$@" > /dev/null 2>&1
  $B eval --truth "$D/truth.nav" --nav "$out/o$ms/navresult.nav" --json "$out/e$ms.json" > /dev/null
  $B fuse --config "$out/cfg$ms.yaml" --output "$out/n$ms" > /dev/null 2>&1
  $B eval --truth "$D/truth.nav" --nav "$out/n$ms/navresult.nav" --json "$out/n$ms.json" > /dev/null
  python3 - "$ms" "$out" <<'PY'
import json, sys
ms, out = float(sys.argv[1]), sys.argv[2]
tag = sys.argv[1]
rows = [l.split() for l in open(f"{out}/o{tag}/time_offset.txt") if not l.startswith("#")]
rows = [(float(a), float(b) * 1e3, float(c) * 1e3) for a, b, c, *_ in rows]
start = rows[0][0]
drive = start + 60.0  # the drive leaves its standstill at +60 s
at60 = min(rows, key=lambda r: abs(r[0] - (drive + 60.0)))
after = [r for r in rows if r[0] >= drive + 60.0]
worst = max(abs(r[1] - ms) / r[2] for r in after)
t, est, sd = rows[-1]
e = json.load(open(f"{out}/e{tag}.json"))["pos_horizontal_m"]["rms"]
s = json.load(open(f"{out}/sync.json"))["pos_horizontal_m"]["rms"]
n = json.load(open(f"{out}/n{tag}.json"))["pos_horizontal_m"]["rms"]
print(f"| {ms:+.0f} | {at60[1]-ms:+.3f} | {est:.3f} | {est-ms:+.3f} | {sd:.3f} | {worst:.2f} | {e:.4f} | {e/s:.3f} | {n:.3f} |")
PY
done
echo "synchronized (true tags, no offset state): horizontal RMS $(python3 -c "import json;print(round(json.load(open('$out/sync.json'))['pos_horizontal_m']['rms'],4))") m"
rm -rf "$out"
