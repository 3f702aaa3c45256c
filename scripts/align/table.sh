#!/usr/bin/env bash
# Initial alignment without initatt/initpos/initvel, on simulated test-track
# drives (400 s): ADIS16465 and ICM-20602, several seeds, starting with a
# 40 s standstill and starting in motion at 12 m/s. Prints the heading error
# 10 s after the vehicle first moves, and the horizontal RMS of the aligned
# run against the run initialised from truth, over the same epochs.
#
# Usage (from the repository root): scripts/align/table.sh [SEED...]
# MISALIGN_STATES=1: both runs also estimate the axis misalignments
# (--misalignment at the datasheet σ), as docs/alignment.md's second table.
# Needs: cargo build --release; python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${NAVSYNC:-target/release/navsync}
W=${WORK:-target/align}
SEEDS=${*:-1 2 3}
mkdir -p "$W"
printf "%-10s %-11s %-5s %16s %12s %12s %8s\n" imu start seed yaw_err_10s_deg rms_aligned rms_truth ratio
for grade in adis16465 icm20602; do
  for start in standstill motion; do
    for seed in $SEEDS; do
      sim="$W/$grade-$start-$seed"
      extra=()
      [ "$start" = motion ] && extra=(--set initial_speed_mps=12)
      "$B" simulate --quiet --internal-rate 0 --scenario test-track --duration 400 \
        --imu-grade "$grade" --seed "$seed" "${extra[@]}" --output "$sim"
      grep -v '^initpos:\|^initvel:\|^initatt:' "$sim/kf-gins.yaml" > "$sim/kf-gins-align.yaml"
      mis=$([ "$grade" = icm20602 ] && echo 0.3 || echo 0.05)
      states=()
      [ "${MISALIGN_STATES:-0}" = 1 ] && states=(--misalignment "$mis")
      "$B" fuse --config "$sim/kf-gins.yaml" "${states[@]}" --output "$sim/truth-init" >/dev/null 2>&1
      # The datasheet's accelerometer axis misalignment (the presets':
      # ADIS16465 0.05°, ICM-20602 0.3°), as a sensor sheet gives it.
      "$B" fuse --config "$sim/kf-gins-align.yaml" --accel-misalignment "$mis" "${states[@]}" \
        --output "$sim/aligned" >/dev/null 2>&1
      read -r _ yaw ra rr ratio < <(python3 scripts/align/heading_check.py "$sim/truth.nav" \
        "$sim/aligned/navresult.nav" "$sim/truth-init/navresult.nav")
      printf "%-10s %-11s %-5s %16s %12s %12s %8s\n" "$grade" "$start" "$seed" "$yaw" "$ra" "$rr" "$ratio"
    done
  done
done
