#!/usr/bin/env bash
# An array of 4 simulated ADIS16465-class IMUs on one vehicle (same drive,
# independent sensor errors: seeds 1–4), their time tags late by 0, 10, 15
# and 20 ms (the case of Wang, Guan & Ding 2019: each unit's data reach the logger late by
# its own delay, all stamped on one grid), fused by `navsync array`.
# Usage: docs/offset/run_array.sh [scenario]   (after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${NAVSYNC:-target/release/navsync}
scn=${1:-urban}
out=$(mktemp -d)
args=()
for i in 1 2 3 4; do
  $B simulate --scenario "$scn" --seed "$i" --internal-rate 0 --set output.rig_log=false --output "$out/s$i" --quiet
  n=$(echo "0 2 3 4" | cut -d' ' -f"$i")   # 0, 10, 15, 20 ms at 200 Hz
  # The logger stamps every IMU on one grid t_k; IMU i's data are n samples
  # late: line k carries the increments of t_(k-n). Lines before t_4 are
  # dropped so that all files share one grid.
  python3 - "$out/s$i/imu.txt" "$n" > "$out/imu$i.txt" <<'PY'
import sys
rows = [l.split() for l in open(sys.argv[1]) if l.strip() and not l.startswith("#")]
n = int(sys.argv[2])
for k in range(4, len(rows)):
    print(" ".join([rows[k][0]] + rows[k - n][1:]))
PY
  args+=(--imu "$out/imu$i.txt")
done
$B array "${args[@]}" --gnss "$out/s1/gnss.txt" --config "$out/s1/kf-gins.yaml" --truth "$out/s1/truth.nav" --output "$out/array"
rm -rf "$out"
