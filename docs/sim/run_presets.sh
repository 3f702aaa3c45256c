#!/usr/bin/env bash
# Simulated drives for each IMU preset through `navsync fuse` and `navsync
# eval`: all GNSS, then 60 s outages every 180 s from +120 s. Usage:
#   docs/sim/run_presets.sh [scenario] [seed]     (after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${NAVSYNC:-target/release/navsync}
scn=${1:-urban}; seed=${2:-1}
out=$(mktemp -d)
printf '| preset | horiz. RMS (m) | 3D RMS (m) | yaw RMS (deg) | RMS of max horiz. drift per outage (m) | worst (m) |\n|---|---|---|---|---|---|\n'
for g in nav tactical adis16465 icm20602; do
  d=$out/$g
  $B simulate --scenario "$scn" --seed "$seed" --imu-grade "$g" --output "$d" --quiet
  $B fuse --config "$d/kf-gins.yaml" --output "$d/all" ${FUSE_EXTRA:-} > /dev/null 2>&1
  $B eval --truth "$d/truth.nav" --nav "$d/all/navresult.nav" --json "$d/all.json" > /dev/null
  $B fuse --config "$d/kf-gins.yaml" --output "$d/out" --outage-period 180 --outage-len 60 --outage-first 120 ${FUSE_EXTRA:-} > "$d/fuse.txt" 2>&1
  o=$(sed -n 's/.*outages (for `navsync eval --outages`): //p' "$d/fuse.txt")
  $B eval --truth "$d/truth.nav" --nav "$d/out/navresult.nav" --outages "$o" --json "$d/out.json" > /dev/null
  python3 - "$g" "$d/all.json" "$d/out.json" <<'PY'
import json, sys
g, a, o = sys.argv[1], json.load(open(sys.argv[2])), json.load(open(sys.argv[3]))
print(f"| {g} | {a['pos_horizontal_m']['rms']:.3f} | {a['pos_3d_m']['rms']:.3f} | {a['yaw_deg']['rms']:.3f} | {o['outage_rms_max_horizontal_m']:.3f} | {o['outage_worst_horizontal_m']:.3f} |")
PY
done
rm -rf "$out"
