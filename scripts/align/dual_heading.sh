#!/usr/bin/env bash
# Dual-antenna heading on simulated drives (ADIS16465, seed 3): the 400 s
# test track and the 60 s static drive, aligned without an initial
# attitude, with and without 5 Hz baseline headings (0.2° noise, 30°
# mounting yaw). Prints the alignment notes and the yaw/horizontal errors
# quoted in docs/alignment.md.
# Usage (repository root, after cargo build --release): scripts/align/dual_heading.sh [WORK_DIR]
set -euo pipefail
cd "$(dirname "$0")/../.."
N=${NAVSYNC:-target/release/navsync}
W=${1:-target/dual-heading}
mkdir -p "$W"
for sc in test-track:400 static:60; do
  name=${sc%%:*}; dur=${sc##*:}
  "$N" simulate --quiet --internal-rate 0 --scenario "$name" --duration "$dur" \
    --imu-grade adis16465 --seed 3 --output "$W/$name" > /dev/null
  grep -v '^initpos:\|^initvel:\|^initatt:' "$W/$name/kf-gins.yaml" > "$W/$name/kf-gins-align.yaml"
  python3 scripts/align/dual_heading.py "$W/$name/truth.nav" "$W/$name/heading.txt" 30 0.2
  for run in course dual; do
    extra=(); [ "$run" = dual ] && extra=(--heading "$W/$name/heading.txt" --dual-antenna-yaw 30)
    "$N" fuse --config "$W/$name/kf-gins-align.yaml" "${extra[@]}" --output "$W/$name/$run" > "$W/$name/$run.log" 2>&1
    echo "## $name, $run"
    grep -E "alignment:|heading updates" "$W/$name/$run.log"
    "$N" eval --truth "$W/$name/truth.nav" --nav "$W/$name/$run/navresult.nav" | grep -E "position horizontal|^yaw"
    tail -1 "$W/$name/$run/std.txt" | awk '{print "final yaw σ (deg) " $10}'
  done
done
