#!/usr/bin/env bash
# Placed faults (issue 33): one episode at a time, at fixed places, on the
# 240 s test-track drive (1 Hz RTK; `navsync simulate`, seed 1) with an
# ADIS16465 and an ICM-20602: ramps growing to 1.5 and 3 m over 12 and
# 20 s, and false fixes of 0.7, 1.5, 3 and 6 m for 10 s, each starting 40,
# 70, 100, 130, 160 and 190 s into the drive, pointing north and 120°
# (`navsync faults --plan`). Each case is fused forward (`fuse
# --no-gnss-velocity`) by NAVSYNC, by BASE if given (another build, to
# compare), and with the episode's fixes left out (the oracle, by NAVSYNC);
# prints one row per case (horizontal RMS, m, by `navsync eval`) and, with
# BASE, how many cases NAVSYNC made better or worse than BASE by more
# than 2 %. Where the bed (table.sh) draws sizes and places from seeds,
# this sweeps them, to see what a change does case by case.
#
# Usage (from the repository root): scripts/integrity/placed.sh
# NAVSYNC=path (default target/release/navsync); BASE=path; WORK=dir
# (default target/integrity-placed); GRADES="adis16465"; ~4 min per grade
# on 2 shared cores with BASE. Needs: cargo build --release; python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
B=$(realpath "${NAVSYNC:-target/release/navsync}")
BASE=${BASE:+$(realpath "$BASE")}
W=${WORK:-target/integrity-placed}
GRADES=${GRADES:-adis16465 icm20602}
HERE=$(pwd)/scripts/integrity
mkdir -p "$W"
W=$(cd "$W" && pwd)
# hrms TRUTH RUN: the horizontal RMS of RUN/navresult.nav; the 200 Hz
# files are deleted once scored (~10 MB a run).
hrms() {
  "$B" eval --truth "$1" --nav "$2/navresult.nav" --json "$2.eval.json" >/dev/null
  rm -f "$2/navresult.nav" "$2/std.txt" "$2/imu_err.txt"
  python3 -c "import json,sys; print(round(json.load(open(sys.argv[1]))['pos_horizontal_m']['rms'], 3))" "$2.eval.json"
}
# fuse BIN SIM GNSS OUT
fuse() {
  python3 "$HERE/bed.py" config "$2/kf-gins.yaml" "$4.yaml" "$2/imu.txt" "$3"
  "$1" fuse --config "$4.yaml" --output "$4" --no-gnss-velocity >/dev/null 2>"$4.log" \
    || { echo "fuse failed ($4.log):" >&2; tail -3 "$4.log" >&2; exit 1; }
}
better=0
worse=0
printf '%-10s %-9s %6s %5s %5s %5s  %8s %8s %8s\n' imu class start_s dur_s size_m dir_deg navsync base oracle
for grade in $GRADES; do
  sim="$W/$grade"
  [ -f "$sim/truth.nav" ] || "$B" simulate --scenario test-track --duration 240 --seed 1 \
    --quiet --output "$sim" --imu-grade "$grade" >/dev/null
  first=$(awk '!/^#/ && NF {print $1; exit}' "$sim/gnss.txt")
  cases() {
    for start in 40 70 100 130 160 190; do
      for dir in 0 120; do
        for dur in 12 20; do for size in 1.5 3; do echo "ramp $start $dur $size $dir"; done; done
        for size in 0.7 1.5 3 6; do echo "false-fix $start 10 $size $dir"; done
      done
    done
  }
  while read -r class start dur size dir; do
    case="$W/$grade-$class-$start-$dur-$size-$dir"
    mkdir -p "$case"
    python3 - "$first" "$start" "$dur" "$size" "$dir" "$class" > "$case/plan.txt" <<'EOF'
import math, sys
first, start, dur, size, deg, cls = sys.argv[1:]
n, e = float(size) * math.cos(math.radians(float(deg))), float(size) * math.sin(math.radians(float(deg)))
print(f"{cls} {float(first) + float(start):.3f} {dur} {n:.4f} {e:.4f} 0")
EOF
    rm -rf "$case/faults"
    "$B" faults --gnss "$sim/gnss.txt" --output "$case/faults" --plan "$case/plan.txt" >/dev/null 2>&1
    python3 "$HERE/bed.py" drop "$case/faults/gnss.txt" "$case/faults/faults.txt" "$case/oracle.txt"
    fuse "$B" "$sim" "$case/faults/gnss.txt" "$case/new"
    fuse "$B" "$sim" "$case/oracle.txt" "$case/oracle"
    new=$(hrms "$sim/truth.nav" "$case/new")
    oracle=$(hrms "$sim/truth.nav" "$case/oracle")
    base=-
    if [ -n "$BASE" ]; then
      fuse "$BASE" "$sim" "$case/faults/gnss.txt" "$case/base"
      base=$(hrms "$sim/truth.nav" "$case/base")
      if python3 -c "import sys; sys.exit(0 if $new < 0.98 * $base else 1)"; then better=$((better + 1)); fi
      if python3 -c "import sys; sys.exit(0 if $new > 1.02 * $base else 1)"; then worse=$((worse + 1)); fi
    fi
    printf '%-10s %-9s %6s %5s %5s %5s  %8s %8s %8s\n' "$grade" "$class" "$start" "$dur" "$size" "$dir" "$new" "$base" "$oracle"
  done < <(cases)
done
if [ -n "$BASE" ]; then echo "better than BASE: $better; worse: $worse"; fi
