#!/usr/bin/env bash
# Real-time GNSS latency handling on the shared simulated drive: every fix
# reaches the filter 100 ms after its time of validity. Accuracy of the
# real-time output against the truth, and cost, for each mode (offline:
# post-processing, every fix at its time of validity, for reference).
# Usage: docs/offset/run_latency.sh [latency_s]   (after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/../.."
B=$(pwd)/${NAVSYNC:-target/release/navsync}
D=${DATA:-$(pwd)/../shared/data/sim-drive-adis16465}
lat=${1:-0.1}
out=$(mktemp -d)
sed "s#\./imu.txt#$D/imu.txt#; s#\./gnss.txt#$D/gnss.txt#" "$D/kf-gins.yaml" > "$out/cfg.yaml"
printf '| mode | horiz. RMS (m) | 3D RMS (m) | yaw RMS (deg) | max horiz. (m) | fuse wall time, median of 5 (s) | CPU / offline |\n|---|---|---|---|---|---|---|\n'
base=""
for mode in offline naive fixed extrapolate delayed; do
  times=()
  for r in 1 2 3 4 5; do
    s=$(date +%s.%N)
    if [ "$mode" = offline ]; then extra=(); else extra=(--gnss-latency "$lat"); fi
    $B fuse --config "$out/cfg.yaml" --output "$out/$mode" --latency-mode "$mode" "${extra[@]}" > /dev/null
    e=$(date +%s.%N)
    times+=("$(python3 -c "print($e - $s)")")
  done
  cpu=$(python3 -c "import json; print(json.load(open('$out/$mode/summary.json'))['run_time_s'])")
  [ -z "$base" ] && base=$cpu
  $B eval --truth "$D/truth.nav" --nav "$out/$mode/navresult.nav" --json "$out/$mode.json" > /dev/null
  python3 - "$mode" "$out/$mode.json" "$cpu" "$base" "${times[@]}" <<'PY'
import json, sys
mode, j, cpu, base = sys.argv[1], json.load(open(sys.argv[2])), float(sys.argv[3]), float(sys.argv[4])
t = sorted(map(float, sys.argv[5:]))
print(f"| {mode} | {j['pos_horizontal_m']['rms']:.4f} | {j['pos_3d_m']['rms']:.4f} | {j['yaw_deg']['rms']:.4f} | {j['pos_horizontal_m']['max']:.4f} | {t[len(t)//2]:.3f} | {cpu/base:.2f} |")
PY
done
rm -rf "$out"
