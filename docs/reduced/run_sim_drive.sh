#!/usr/bin/env bash
# Reduced-IMU drift table on the simulated ADIS16465 drive.
# Usage: docs/reduced/run_sim_drive.sh [OUT_DIR]   (from the repository root)
set -euo pipefail
N=$(realpath "${NAVSYNC:-target/release/navsync}")
D=${DATA:-$(realpath ../shared/data/sim-drive-adis16465)}
O=$(realpath -m "${1:-/tmp/navsync-reduced}")
mkdir -p "$O"
# Simulated odometer: forward speed of the truth at 20 Hz, +1 % scale error,
# 0.05 m/s white noise, 0.01 m/s resolution.
$N speed-sim --truth $D/truth.nav --out "$O/speed.txt" --rate 20 --scale-error 0.01 --noise 0.05 --resolution 0.01 --seed 1
OUT="--outage-period 180 --outage-len 60 --outage-first 120"
run() { # name, extra fuse args
  (cd $D && $N fuse --config kf-gins.yaml --output "$O/$1" $OUT "${@:2}") > "$O/$1.log"
  local outages
  outages=$(python3 -c "import json,sys;print(json.load(open(sys.argv[1]))['outages'])" "$O/$1/summary.json")
  $N eval --truth $D/truth.nav --nav "$O/$1/navresult.nav" --outages "$outages" --json "$O/$1/eval.json" > "$O/$1/eval.txt"
}
run full
run full_nhc --nhc
run full_odo_nhc --nhc --odometer "$O/speed.txt"
run 1g2a --imu-config 1g2a
run 1g2a_nhc --imu-config 1g2a --nhc
run 1g2a_odo_nhc --imu-config 1g2a --nhc --odometer "$O/speed.txt"
run 1g3a_odo_nhc --imu-config 1g3a --nhc --odometer "$O/speed.txt"
python3 - "$O" <<'PY'
import json, sys, os
o = sys.argv[1]
rows = ["full", "full_nhc", "full_odo_nhc", "1g2a", "1g2a_nhc", "1g2a_odo_nhc", "1g3a_odo_nhc"]
print("| case | RMS of max horiz. drift per outage (m) | worst (m) | horiz. RMS all epochs (m) | yaw RMS (deg) | odo scale est. |")
print("|---|---|---|---|---|---|")
for r in rows:
    e = json.load(open(os.path.join(o, r, "eval.json")))
    s = json.load(open(os.path.join(o, r, "summary.json")))
    d = [x["max_horizontal_m"] for x in e["outages"]]
    rms = (sum(x * x for x in d) / len(d)) ** 0.5
    k = s.get("final_odometer_scale")
    print(f"| {r} | {rms:.3f} | {max(d):.3f} | {e['pos_horizontal_m']['rms']:.3f} | {e['yaw_deg']['rms']:.3f} | {'' if k is None else f'{100*k:+.3f} %'} |")
PY
