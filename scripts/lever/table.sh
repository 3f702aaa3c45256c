#!/usr/bin/env bash
# The lever-arm states' table of docs/lever-arm.md: simulated drives with
# the antenna at [0.4, -0.3, -0.8] m, processed with the right sheet, a zero
# sheet, the zero sheet with `estimate_lever_arm: true` and the right sheet
# with it; prints a Markdown table (horizontal RMS against the truth, the
# estimate and its σ, the verdict's lever-arm checks).
#
# Usage (repository root, after cargo build --release):
#   scripts/lever/table.sh [WORK_DIR]      (default target/lever-table)
# SEEDS="1", SCENARIOS="test-track urban", GRADES="adis16465 icm20602",
# DURATION=300 override. Needs python3 (stdlib). About 10 s a drive.
set -euo pipefail
cd "$(dirname "$0")/../.."
export NAVSYNC=$(realpath "${NAVSYNC:-target/release/navsync}")
export WORK=$(realpath -m "${1:-target/lever-table}")
export SEEDS=${SEEDS:-1} SCENARIOS=${SCENARIOS:-test-track urban}
export GRADES=${GRADES:-adis16465 icm20602} DURATION=${DURATION:-300}
exec python3 scripts/lever/table.py
