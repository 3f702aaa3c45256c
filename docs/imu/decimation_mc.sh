#!/usr/bin/env bash
# Averaging vs point decimation (Tang, Zhang & Niu 2022 §1.3): an ADIS16465-class IMU
# sampling internally at 2 kHz with car vibration (road band 10–60 Hz plus
# engine tones at 101.5 and 203 Hz), decimated to 200 Hz either way; the
# same drive and the same sensor errors (each source has its own random
# stream), fused with 60 s GNSS outages every 180 s from +120 s.
# Usage: docs/imu/decimation_mc.sh [runs] [scenario]   (after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${NAVSYNC:-target/release/navsync}
runs=${1:-10}; scn=${2:-urban}
out=$(mktemp -d)
for seed in $(seq 1 "$runs"); do
  for m in average point; do
    d=$out/$m$seed
    $B simulate --scenario "$scn" --seed "$seed" --internal-rate 2000 --vibration car --decimation $m --output "$d" --quiet
    $B fuse --config "$d/kf-gins.yaml" --output "$d/out" --outage-period 180 --outage-len 60 --outage-first 120 > "$d/fuse.txt" 2>&1
    o=$(sed -n 's/.*outages (for `navsync eval --outages`): //p' "$d/fuse.txt")
    $B eval --truth "$d/truth.nav" --nav "$d/out/navresult.nav" --outages "$o" --json "$d/eval.json" > /dev/null
    rm -f "$d"/*.txt "$d"/rig.csv "$d"/truth.nav "$d"/out/navresult.nav
  done
done
python3 - "$out" "$runs" <<'PY'
import json, sys, math
out, runs = sys.argv[1], int(sys.argv[2])
print("| seed | average: RMS max horiz. drift (m) | point (m) | point / average |")
print("|---|---|---|---|")
agg = {"average": [], "point": []}
for s in range(1, runs + 1):
    v = {m: json.load(open(f"{out}/{m}{s}/eval.json"))["outage_rms_max_horizontal_m"] for m in agg}
    for m in agg: agg[m].append(v[m])
    print(f"| {s} | {v['average']:.2f} | {v['point']:.2f} | {v['point']/v['average']:.2f} |")
rms = {m: math.sqrt(sum(x*x for x in agg[m]) / runs) for m in agg}
wins = sum(a < p for a, p in zip(agg["average"], agg["point"]))
print(f"| RMS over {runs} runs | {rms['average']:.2f} | {rms['point']:.2f} | {rms['point']/rms['average']:.2f} |")
print(f"averaging better in {wins} of {runs} runs")
PY
rm -rf "$out"
