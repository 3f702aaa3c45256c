#!/usr/bin/env bash
# Hybrid synchronization figures (docs/hybrid-sync.md): the `hybrid` rig
# (1PPS captured on the host counter, IMU stamped at receipt, FIFO) over
# receive-latency laws and counter drifts, synchronized by `navsync sync`
# (auto → hybrid) and, with the pps lines removed, by software sync.
#
#   scripts/hybrid-sync/figures.sh [SEEDS] [OUT]
#
# Prints one markdown row per case and seed: IMU stamp error against the
# simulator's truth (sd about the mean; the mean is the unobservable
# fastest transport latency), losses injected / found / exactly placed,
# samples flagged ambiguous, one period off.
set -euo pipefail
SEEDS=${1:-"1 2 3"}
OUT=${2:-/tmp/navsync-hybrid-figures}
NAVSYNC=${NAVSYNC:-navsync}
mkdir -p "$OUT"

declare -A LAW=(
  [u1-10]="--set rig.software.imu_latency_s=[0.001,0.010]"
  [u1-3]="--set rig.software.imu_latency_s=[0.001,0.003]"
  [exp2]="--set rig.software.imu_latency_law=exponential --set rig.software.imu_latency_s=[0.001,0.001] --set rig.software.imu_latency_mean_s=0.002"
)
declare -A DRIFT=(
  [40ppm+25C]=""
  [100ppm+25C]="--set rig.counter.freq_error_ppm=100 --set rig.counter.temp_coeff_ppm_per_c=1.0"
  [5ppm-flat]="--set rig.counter.freq_error_ppm=5 --set rig.counter.temp_coeff_ppm_per_c=0"
)

row() { # dir label mode
  python3 - "$1" "$2" "$3" <<'PY'
import json, sys, bisect
d, label, mode = sys.argv[1:4]
r = json.load(open(f"{d}/{mode}/sync_report.json"))
s = json.load(open(f"{d}/sim/scenario.json"))
t = r["truth"]
inj = s["report"]["imu_lost"]["count"]
found = r["imu"]["lost"]
# exact places: the record index after each gap against the truth's
sows = [float(l.split()[1]) for l in open(f"{d}/sim/imu_times_truth.txt") if not l.startswith("#")]
truth_idx = {bisect.bisect_left(sows, x) for x in s["report"]["imu_lost"]["first"]}
exact = sum(1 for g in r["imu"]["gaps"] if g["record"] in truth_idx)
# stamps one period (or more) off, against the median error
st = [l.split() for l in open(f"{d}/{mode}/imu_times.txt") if not l.startswith("#")]
e = sorted((float(a[1]) - b) * 1e6 for a, b in zip(st, sows))
med = e[len(e) // 2]
off = sum(1 for x in e if abs(x - med) > 2500)
amb = (r.get("hybrid") or {}).get("ambiguous_samples", "-")
print(f"| {label} | {r['mode']} | {t['sd_us']:.1f} | {t['mean_us']:.0f} | {t['max_abs_us']:.0f} | {inj} | {found} | {exact} | {off} | {amb} |")
PY
}

echo "| case (latency law, counter, seed) | mode | sd µs | mean µs | max µs | lost injected | found | exact place | stamps ≥ ½ period off | flagged ambiguous |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for law in u1-10 u1-3 exp2; do
  for drift in 40ppm+25C 100ppm+25C 5ppm-flat; do
    # the laws over the preset's counter; the drifts under the preset's law
    if [[ $law != u1-10 && $drift != 40ppm+25C ]]; then continue; fi
    for seed in $SEEDS; do
      d="$OUT/$law-$drift-$seed"
      # shellcheck disable=SC2086
      "$NAVSYNC" simulate --quiet --scenario hybrid --seed "$seed" --output "$d/sim" ${LAW[$law]} ${DRIFT[$drift]}
      "$NAVSYNC" sync "$d/sim/rig.csv" --output "$d/hybrid" --truth "$d/sim/imu_times_truth.txt" >/dev/null 2>&1 || true
      row "$d" "$law, $drift, $seed" hybrid
      grep -v '^pps,' "$d/sim/rig.csv" >"$d/sim/rig-nopps.csv"
      "$NAVSYNC" sync "$d/sim/rig-nopps.csv" --output "$d/sw" --truth "$d/sim/imu_times_truth.txt" --force >/dev/null 2>&1 || true
      row "$d" "$law, $drift, $seed, pps removed" sw
    done
  done
done
