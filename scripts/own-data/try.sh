#!/usr/bin/env bash
# docs/own-data.md as a new user would follow it, on (a) a simulated raw
# rig log and (b) the real comma2k19 Example_1 logs; prints the figures of
# docs/own-data.md.
# Usage (repository root, after cargo build --release): scripts/own-data/try.sh [WORK_DIR]
# Needs python3 with numpy for (b)'s reference (docs/reduced/comma2k19_to_kfgins.py).
set -euo pipefail
cd "$(dirname "$0")/../.."
N=$(realpath "${NAVSYNC:-target/release/navsync}")
W=$(realpath -m "${1:-target/own-data}")
S=$(realpath "${DATA:-../shared/data/comma2k19-example1}")
rm -rf "$W" && mkdir -p "$W"
# RMS column of eval's first table (a smoothed solution's comparison follows it).
hrms() { "$N" eval --truth "$1" --nav "$2" | awk '/position horizontal/ {print $4; exit}'; }

echo "## (a) simulated drive: test-track 400 s, ADIS16465, seed 1"
"$N" simulate --quiet --internal-rate 0 --scenario test-track --duration 400 \
  --imu-grade adis16465 --seed 1 --output "$W/sim"
"$N" init --preset adis16465 --output "$W/sim-sensor.yaml" > /dev/null
# The simulator's antenna: 0.1 m forward, 0.5 m right, 1.2 m above the IMU.
sed -i 's/^antenna_lever_m: .*/antenna_lever_m: [0.1, 0.5, -1.2]/' "$W/sim-sensor.yaml"
"$N" process "$W/sim/rig.csv" --sensor "$W/sim-sensor.yaml" --output "$W/sim-run" \
  --truth "$W/sim/truth.nav" > "$W/sim-run.log" 2>&1
"$N" fuse --config "$W/sim/kf-gins.yaml" --output "$W/sim-truth-init" > /dev/null 2>&1
"$N" fuse --config "$W/sim/kf-gins.yaml" --output "$W/sim-truth-init-smooth" --smooth > /dev/null 2>&1
echo "| run | horizontal RMS (m) |"
echo "|---|---|"
echo "| process (aligned, smoothed) | $(hrms "$W/sim/truth.nav" "$W/sim-run/fuse/navresult.nav") |"
echo "| process, forward filter | $(hrms "$W/sim/truth.nav" "$W/sim-run/fuse/forward/navresult.nav") |"
echo "| fuse from truth, forward | $(hrms "$W/sim/truth.nav" "$W/sim-truth-init/navresult.nav") |"
echo "| fuse --smooth from truth | $(hrms "$W/sim/truth.nav" "$W/sim-truth-init-smooth/navresult.nav") |"

echo "## (b) comma2k19 Example_1 (no reference used for the initial state)"
"$N" init --preset icm20602 --output "$W/phone.yaml" > /dev/null
# A phone IMU with uncalibrated gyros; u-blox fixes without σ.
sed -i -e 's/^  arw_deg_sqrt_h: .*/  arw_deg_sqrt_h: 0.5/' \
  -e 's/^  vrw_mps_sqrt_h: .*/  vrw_mps_sqrt_h: 0.3/' \
  -e 's/^  gyro_bias_instability_deg_h: .*/  gyro_bias_instability_deg_h: 50.0/' \
  -e 's/^  accel_bias_instability_mgal: .*/  accel_bias_instability_mgal: 500.0/' \
  -e 's/^  gyro_turn_on_bias_deg_h: .*/  gyro_turn_on_bias_deg_h: 7200.0/' \
  -e 's/^  accel_turn_on_bias_mgal: .*/  accel_turn_on_bias_mgal: 30000.0/' \
  -e 's/^  gyro_scale_ppm: .*/  gyro_scale_ppm: 5000.0/' \
  -e 's/^  accel_scale_ppm: .*/  accel_scale_ppm: 5000.0/' \
  -e 's/^gnss_default_sd_m: .*/gnss_default_sd_m: [1.0, 1.0, 2.0]/' "$W/phone.yaml"
cp "$W/phone.yaml" "$W/phone-edited.yaml"
"$N" init --preset icm20602 --output "$W/phone.yaml" --force > /dev/null
mv "$W/phone.yaml" "$W/untouched.yaml" && mv "$W/phone-edited.yaml" "$W/phone.yaml"
# The reference, for scoring only (comma's pose, camera frame, boot + 357697.8495 s).
python3 docs/reduced/comma2k19_to_kfgins.py "$S" "$W/comma-ref" > /dev/null
"$N" process "$S/gnss_ublox.csv" "$S/imu.csv" --sensor "$W/phone.yaml" \
  --output "$W/comma-run" --truth "$W/comma-ref/truth.nav" > "$W/comma-run.log" 2>&1
grep -E "time offset \(|alignment:" "$W/comma-run.log" | head -2
# The same with the untouched icm20602 sheet (what docs/own-data.md §5 is about).
"$N" process "$S/gnss_ublox.csv" "$S/imu.csv" --sensor "$W/untouched.yaml" \
  --output "$W/comma-untouched" > "$W/comma-untouched.log" 2>&1
# Initialised from the reference, on the reference's clock (docs/smoothing.md).
"$N" fuse --config "$W/comma-ref/kf-gins.yaml" --output "$W/comma-ref-init" > /dev/null 2>&1
"$N" fuse --config "$W/comma-ref/kf-gins.yaml" --output "$W/comma-ref-init-smooth" --smooth > /dev/null 2>&1
echo "| solution | horizontal RMS (m) | 3D RMS (m) | yaw RMS (deg) |"
echo "|---|---|---|---|"
for s in comma-run/fuse/navresult.nav comma-run/fuse/forward/navresult.nav \
  comma-untouched/fuse/navresult.nav comma-ref-init/navresult.nav comma-ref-init-smooth/navresult.nav; do
  "$N" eval --truth "$W/comma-ref/truth.nav" --nav "$W/$s" |
    awk -v s="$s" '/position horizontal/ && !h {h=$4} /position 3D/ && !d {d=$4} /^yaw/ && !y {y=$3} END {printf "| %s | %s | %s | %s |\n", s, h, d, y}'
done
