#!/usr/bin/env bash
# Forward filter against the RTS smoother (`fuse --smooth`) on the real-GNSS
# test bed of table.sh (an exact IMU simulated along the shared dataset2
# reference drive, its real GNSS fixes replayed): horizontal RMS (m) with
# all fixes, and the RMS of the per-outage maximum horizontal drift (m) with
# 30 s outages every 120 s, forward and smoothed, robust weighting.
#
# Usage (from the repository root): scripts/real-gnss/smooth.sh [SEED...]
# Needs: cargo build --release; python3 (for the JSON fields).
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${NAVSYNC:-target/release/navsync}
D=../shared/data/kfgins-matlab-dataset2
W=${WORK:-target/real-gnss}
SEEDS=${*:-1}
VEL=${VEL:---no-gnss-velocity}
mkdir -p "$W"
field() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))$2)" "$1"; }
ev() { "$B" eval --truth "$1" --nav "$2/navresult.nav" --json "$2/eval.json" ${3:+--outages "$3"} >/dev/null; }
printf "%-10s %-5s %12s %12s %8s %12s %12s %8s\n" imu seed fwd_rms smooth_rms ratio fwd_outage smooth_outage ratio
for grade in adis16465 icm20602 nav; do
  for seed in $SEEDS; do
    sim="$W/$grade-$seed"
    [ -f "$sim/kf-gins.yaml" ] || "$B" simulate --from-nav "$D/truth.nav" --gnss-real "$D/GNSS-POSVEL.txt" \
      --gnss-real-layout matlab --set 'gnss.lever_arm_m=[-0.37,0.008,0.353]' \
      --gnss-velocity --imu-grade "$grade" --seed "$seed" --quiet --output "$sim"
    out="$sim/smooth"
    "$B" fuse --config "$sim/kf-gins.yaml" --output "$out" --smooth $VEL >/dev/null 2>&1
    ev "$sim/truth.nav" "$out/forward"; ev "$sim/truth.nav" "$out"
    hf=$(field "$out/forward/eval.json" "['pos_horizontal_m']['rms']")
    hs=$(field "$out/eval.json" "['pos_horizontal_m']['rms']")
    "$B" fuse --config "$sim/kf-gins.yaml" --output "$out-outage" --smooth $VEL \
      --outage-period 120 --outage-len 30 --outage-first 60 >/dev/null 2>&1
    o=$(field "$out-outage/summary.json" "['outages']")
    ev "$sim/truth.nav" "$out-outage/forward" "$o"; ev "$sim/truth.nav" "$out-outage" "$o"
    df=$(field "$out-outage/forward/eval.json" "['outage_rms_max_horizontal_m']")
    ds=$(field "$out-outage/eval.json" "['outage_rms_max_horizontal_m']")
    printf "%-10s %-5s %12.3f %12.3f %8.3f %12.3f %12.3f %8.3f\n" "$grade" "$seed" "$hf" "$hs" \
      "$(python3 -c "print($hs/$hf)")" "$df" "$ds" "$(python3 -c "print($ds/$df)")"
  done
done
