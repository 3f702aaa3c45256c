#!/usr/bin/env bash
# docs/smoothing.md's comma2k19 table: forward vs smoothed (`fuse --smooth`)
# on comma2k19 Example_1, converted as docs/reduced/run_comma2k19.sh does
# (GNSS σ 2 m horizontal, 3 m vertical), scored against comma's
# post-processed pose by `navsync eval` (which scores forward/ beside it).
# Usage (from the repository root): scripts/smoothing/comma2k19.sh [WORK]
# Needs: cargo build --release; python3 with numpy (the converter);
# ../shared/data/comma2k19-example1 (or DATA=...).
set -euo pipefail
cd "$(dirname "$0")/../.."
B=$(realpath "${NAVSYNC:-target/release/navsync}")
S=${DATA:-../shared/data/comma2k19-example1}
O=$(realpath -m "${1:-target/smoothing-comma2k19}")
mkdir -p "$O"
python3 docs/reduced/comma2k19_to_kfgins.py "$S" "$O" --gnss-sd 2 3 > "$O/convert.txt"
MOUNT=$(sed -n 's/.*--mount \(.*\)$/\1/p' "$O/convert.txt")
OUT="--outage-period 30 --outage-len 15 --outage-first 10"
VEH="--nhc --mount $MOUNT --odometer $O/speed.txt --odo-sd 0.1"
run() { # name, extra fuse args
  "$B" fuse --config "$O/kf-gins.yaml" --output "$O/$1" --smooth "${@:2}" > "$O/$1.log" 2>&1
  local outages
  outages=$(python3 -c "import json,sys;print(json.load(open(sys.argv[1]))['outages'])" "$O/$1/summary.json")
  "$B" eval --truth "$O/truth.nav" --nav "$O/$1/navresult.nav" ${outages:+--outages "$outages"} \
    --json "$O/$1/eval.json" > /dev/null 2>&1
}
run all
# shellcheck disable=SC2086
run vehicle_out $OUT $VEH
# shellcheck disable=SC2086
run imu_out $OUT
python3 - "$O" <<'PY'
import json, os, sys, datetime
o = sys.argv[1]
names = {"all": "all GNSS", "vehicle_out": "15 s outages every 30 s, NHC + CAN speed",
         "imu_out": "15 s outages, IMU only"}
print(f"(scripts/smoothing/comma2k19.sh, {datetime.date.today()})")
print("| case | horizontal RMS, forward → smoothed | yaw RMS | outage drift |")
print("|---|---|---|---|")
for r, name in names.items():
    e = json.load(open(os.path.join(o, r, "eval.json")))
    f = e["forward"]
    h, hf = e["pos_horizontal_m"]["rms"], f["pos_horizontal_m"]["rms"]
    y, yf = e["yaw_deg"]["rms"], f["yaw_deg"]["rms"]
    d = "–"
    if e.get("outages"):
        dd, df = e["outage_rms_max_horizontal_m"], f["outage_rms_max_horizontal_m"]
        d = f"{df:.2f} → {dd:.2f} m ({dd / df:.2f})"
    print(f"| {name} | {hf:.3f} → {h:.3f} m ({h / hf:.2f}) | {yf:.2f}° → {y:.2f}° | {d} |")
PY
