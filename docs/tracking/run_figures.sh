#!/usr/bin/env bash
# Reproduces the carrier-tracking figures (docs/tracking/README.md).
# Usage: docs/tracking/run_figures.sh [OUT_DIR]   (from the repository root)
set -euo pipefail
N=${NAVSYNC:-target/release/navsync}
O=${1:-docs/tracking}
mkdir -p "$O"
# Thermal jitter against Kaplan & Hegarty (static receiver, perfect oscillator).
$N track --scenario static --sat-rate 0 --sat-accel 0 --oscillator ideal --order 2 --bandwidth 10 \
  --cn0 25:45:5 --duration 150 --csv "$O/thermal.csv" | tee "$O/thermal.txt"
# The GPS Solutions paper's eq 16: a 1 Hz/s aiding ramp in the aided 2nd-order 3 Hz loop.
$N track --scenario static --sat-rate 0 --sat-accel 0 --oscillator ideal --aiding ins --aiding-error ramp:1 \
  --order 2 --bandwidth 3 --cn0 60 --duration 20 --settle 5 | tee "$O/ramp.txt"
# Thresholds: unaided 3rd order 15 Hz vs INS-aided 2nd order 3 Hz, land vehicle, T = 1 and 20 ms.
for T in 1 20; do
  $N track --cn0 15:40 --duration 300 --order 3 --bandwidth 15 --t-coh $T \
    --csv "$O/unaided15_T$T.csv" --svg "$O/unaided15_T$T.svg" | tee "$O/unaided15_T$T.txt"
  $N track --cn0 15:40 --duration 300 --aiding ins --order 2 --bandwidth 3 --t-coh $T \
    --csv "$O/aided3_T$T.csv" --svg "$O/aided3_T$T.svg" | tee "$O/aided3_T$T.txt"
done
# Adaptive vs the best fixed bandwidth, aiding quality alternating every 30 s.
for T in 1 20; do
  $N track --cn0 25:45 --duration 120 --aiding ins --aiding-error varying --bandwidth adaptive --t-coh $T \
    --compare-fixed 1,1.5,2,3,4,5,6,8,10,12,15,18,22 \
    --csv "$O/adaptive_T$T.csv" --svg "$O/adaptive_T$T.svg" --series 30 "$O/adaptive_T${T}_series30.csv" \
    | tee "$O/adaptive_T$T.txt"
done
