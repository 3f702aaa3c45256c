#!/usr/bin/env bash
# comma2k19 Example_1: the IMU's boot-clock → GPS-time relation from imu.csv
# and gnss_ublox.csv alone, checked against reference_pose.csv.
#
# 1. Software sync of the GNSS stream (Tang, Zhang & Niu 2022 §2.2, TICSync): every fix
#    carries its time of validity (UTC + 18 s) and its boot time at
#    receipt; latency is never negative, so GPS = boot + c with
#    c ≥ max_k(valid_k − boot_k) = c0 (equality for the fastest message).
# 2. The IMU, stamped at arrival on the same boot clock, is put on GPS
#    time with c0; what remains is the fastest GNSS latency minus the
#    IMU's own arrival delay: the time offset the filter estimates
#    (`navsync fuse --estimate-time-offset`, coarse search ±0.5 s first),
#    with the initial state from the first fixes (no reference used).
# 3. IMU boot → GPS = c0 + τ (τ = GNSS tag − true validity on the IMU's
#    time base), against the reference mapping 357697.8495 s.
# Usage: docs/comma2k19/boot_to_gps.sh [OUT_DIR]   (after cargo build --release)
set -euo pipefail
N=$(realpath "${NAVSYNC:-target/release/navsync}")
S=${DATA:-$(realpath "$(dirname "$0")/../../../shared/data/comma2k19-example1")}
O=$(realpath -m "${1:-$(mktemp -d)}")
mkdir -p "$O"
# u-blox fixes carry no σ here: the assumed one matters (see the loop below).
$N convert --from comma-gnss "$S/gnss_ublox.csv" --output "$O/gnss" --default-sd 1,1,2 > /dev/null
c0=$(python3 - "$O/gnss/gnss_receipt.txt" <<'PY'
import sys
rows = [l.split() for l in open(sys.argv[1]) if not l.startswith("#")]
print(f"{max(float(sow) - float(boot) for _, sow, boot in rows):.6f}")
PY
)
echo "GNSS lower envelope: GPS sow = boot + c0, c0 = $c0 s (fastest fix taken as 0 latency)"
$N convert --from rate-csv "$S/imu.csv" --output "$O/imu" --imu-time-offset-s "$c0" > /dev/null
# Initial state from the first fix: position, velocity from speed and
# bearing, heading = bearing; level; phone gyros are uncalibrated (σ 3°/s).
python3 - "$S/gnss_ublox.csv" "$O" <<'PY'
import sys, math
rows = [l.split(",") for l in open(sys.argv[1]) if not l.startswith("#")]
o = sys.argv[2]
_, lat, lon, speed, _, alt, bearing = map(float, rows[0])
b = math.radians(bearing)
first_sow = float(open(f"{o}/imu/imu.txt").readline().split()[0])
open(f"{o}/kf-gins.yaml", "w").write(f"""# comma2k19 Example_1, initial state from the first u-blox fix
imupath: "{o}/imu/imu.txt"
gnsspath: "{o}/gnss/gnss.txt"
outputpath: "{o}/out"
imudatalen: 7
imudatarate: 104
starttime: {first_sow + 0.5:.6f}
endtime: -1
initpos: [ {lat:.9f}, {lon:.9f}, {alt:.3f} ]
initvel: [ {speed*math.cos(b):.3f}, {speed*math.sin(b):.3f}, 0.0 ]
initatt: [ 0.0, 0.0, {bearing:.3f} ]
initgyrbias: [ 0, 0, 0 ]
initaccbias: [ 0, 0, 0 ]
initgyrscale: [ 0, 0, 0 ]
initaccscale: [ 0, 0, 0 ]
initposstd: [ 2.0, 2.0, 3.0 ]
initvelstd: [ 0.5, 0.5, 0.5 ]
initattstd: [ 3.0, 3.0, 5.0 ]
initbgstd: [ 10800.0, 10800.0, 10800.0 ]
initbastd: [ 50000.0, 50000.0, 50000.0 ]
initsgstd: [ 5000.0, 5000.0, 5000.0 ]
initsastd: [ 5000.0, 5000.0, 5000.0 ]
imunoise:
  arw: [ 0.5, 0.5, 0.5 ]
  vrw: [ 0.3, 0.3, 0.3 ]
  gbstd: [ 50.0, 50.0, 50.0 ]
  abstd: [ 500.0, 500.0, 500.0 ]
  gsstd: [ 5000.0, 5000.0, 5000.0 ]
  asstd: [ 5000.0, 5000.0, 5000.0 ]
  corrtime: 1.0
antlever: [ 0.0, 0.0, 0.0 ]
""")
PY
ref_c=$(python3 -c "
rows = [l.split(',') for l in open('$S/reference_pose.csv') if not l.startswith('#')]
print(f'{sum(float(r[2]) - float(r[0]) for r in rows) / len(rows):.4f}')")
echo "reference_pose.csv: GPS sow = boot + $ref_c s"
echo "| assumed GNSS σ N,E,D (m) | filter offset τ (ms) | IMU boot → GPS (s) | estimate − reference (ms) |"
echo "|---|---|---|---|"
for sd in 0.3,0.3,0.6 1,1,2 2,2,3 5,5,10; do
  $N convert --from comma-gnss "$S/gnss_ublox.csv" --output "$O/gnss_$sd" --default-sd "$sd" > /dev/null
  sed "s#$O/gnss/gnss.txt#$O/gnss_$sd/gnss.txt#" "$O/kf-gins.yaml" > "$O/kf-gins_$sd.yaml"
  $N fuse --config "$O/kf-gins_$sd.yaml" --output "$O/out_$sd" --estimate-time-offset > "$O/fuse_$sd.txt" 2>&1 || { cat "$O/fuse_$sd.txt"; exit 1; }
  python3 - "$O/out_$sd/summary.json" "$c0" "$ref_c" "$sd" <<'PY'
import json, sys
s = json.load(open(sys.argv[1])); c0, ref = float(sys.argv[2]), float(sys.argv[3])
tau, sd = s["time_offset_s"], s["time_offset_sd_s"]
# The IMU stamps boot + c0 are early by λ_min − μ: fixes look late by τ.
est = c0 + tau
print(f"| {sys.argv[4]} | {tau*1e3:+.1f} ± {sd*1e3:.1f} | {est:.4f} | {(est - ref)*1e3:+.1f} |")
PY
done
