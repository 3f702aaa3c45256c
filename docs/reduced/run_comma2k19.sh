#!/usr/bin/env bash
# Full IMU vs reduced IMU (1g2a) + CAN speed + NHC on comma2k19 Example_1
# Usage: docs/reduced/run_comma2k19.sh [OUT_DIR]  (repository root)
set -euo pipefail
N=$(realpath "${NAVSYNC:-target/release/navsync}")
S=${DATA:-$(realpath ../shared/data/comma2k19-example1)}
O=$(realpath -m "${1:-/tmp/navsync-comma2k19}")
python3 "$(dirname "$0")/comma2k19_to_kfgins.py" $S "$O" --gnss-sd 2 3 | tee "$O.convert.txt"
MOUNT=$(sed -n 's/.*--mount \(.*\)$/\1/p' "$O.convert.txt")
# 60 s of data: outages of 15 s every 30 s, the first 10 s after the start.
OUT="--outage-period 30 --outage-len 15 --outage-first 10"
VEH="--nhc --mount $MOUNT --odometer $O/speed.txt --odo-sd 0.1"
run() { # name, extra fuse args
  $N fuse --config "$O/kf-gins.yaml" --output "$O/$1" "${@:2}" > "$O/$1.log"
  local outages
  outages=$(python3 -c "import json,sys;print(json.load(open(sys.argv[1]))['outages'])" "$O/$1/summary.json")
  $N eval --truth "$O/truth.nav" --nav "$O/$1/navresult.nav" --outages "$outages" --json "$O/$1/eval.json" > "$O/$1/eval.txt"
}
run full
run full_vehicle $VEH
run 1g2a_vehicle --imu-config 1g2a $VEH
run full_out $OUT
run full_vehicle_out $OUT $VEH
run 1g2a_vehicle_out --imu-config 1g2a $OUT $VEH
run 1g3a_vehicle_out --imu-config 1g3a $OUT $VEH
run 1g2a_out --imu-config 1g2a $OUT
python3 - "$O" <<'PY'
import json, sys, os
o = sys.argv[1]
print("| case | horiz. RMS (m) | horiz. max (m) | max horiz. error per outage (m) | yaw RMS (deg) | CAN scale est. |")
print("|---|---|---|---|---|---|")
for r in ["full", "full_vehicle", "1g2a_vehicle", "full_out", "full_vehicle_out", "1g2a_vehicle_out", "1g3a_vehicle_out", "1g2a_out"]:
    e = json.load(open(os.path.join(o, r, "eval.json")))
    s = json.load(open(os.path.join(o, r, "summary.json")))
    d = ", ".join(f"{x['max_horizontal_m']:.2f}" for x in e["outages"]) or "–"
    k = s.get("final_odometer_scale")
    print(f"| {r} | {e['pos_horizontal_m']['rms']:.2f} | {e['pos_horizontal_m']['max']:.2f} | {d} | {e['yaw_deg']['rms']:.2f} | {'' if k is None else f'{100*k:+.2f} %'} |")
PY
