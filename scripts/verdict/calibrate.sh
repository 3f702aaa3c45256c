#!/usr/bin/env bash
# The verdict's labelled bed (issue 34 item 1): simulated drives (two
# scenarios, three IMU grades, several seeds) through the user's path
# (`navsync process RIG --sensor SHEET`, no truth given), each once with the
# right sheet and once per defect; the truth kept aside measures the
# horizontal RMS and the loss against the clean run of the same drive.
# Prints the confusion matrix (label × verdict) and writes runs.csv.
#
# Usage (repository root, after cargo build --release):
#   scripts/verdict/calibrate.sh [WORK_DIR]      (default target/verdict-bed)
# SEEDS="1 2 3", SCENARIOS="test-track urban", GRADES="adis16465 icm20602 nav",
# DURATION=300, JOBS=2 override the bed; KEEP=1 keeps every run's fuse/ and
# sync/ (about 30 MB a run; the simulations take about 2.4 GB). Needs bash
# and python3 (stdlib).
set -euo pipefail
cd "$(dirname "$0")/../.."
export NAVSYNC=$(realpath "${NAVSYNC:-target/release/navsync}")
export WORK=$(realpath -m "${1:-target/verdict-bed}")
export SEEDS=${SEEDS:-1 2 3} SCENARIOS=${SCENARIOS:-test-track urban}
export GRADES=${GRADES:-adis16465 icm20602 nav} DURATION=${DURATION:-300} JOBS=${JOBS:-2} KEEP=${KEEP:-}
exec python3 scripts/verdict/calibrate.py
