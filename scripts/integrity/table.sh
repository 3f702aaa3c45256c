#!/usr/bin/env bash
# The GNSS integrity bed (issue 33): labelled receiver faults (`navsync
# faults`: spikes, false RTK fixes, ramps, stale repeats) injected into
#   - dataset2's real trajectory with its real fixes (KF-GINS-Matlab
#     dataset2; an exact IMU simulated along it, as scripts/real-gnss/
#     table.sh), IMU grades adis16465, icm20602, nav;
#   - a simulated driving-speed drive (the test-track scenario, 600 s,
#     up to 22 m/s, 1 Hz RTK), adis16465 and icm20602, and the same with
#     10 Hz RTK (drive10-*);
# each with several fault seeds (sizes, durations, directions and
# placements drawn per seed), fused forward and smoothed (`fuse --smooth`)
# with clean fixes, faulty fixes (default weighting), the oracle (the same
# faulty file with the labelled fixes left out) and KF-GINS's rule
# (`--gnss-weighting off`) with the faults. Prints one table (horizontal
# RMS by `navsync eval` against the truth; the ratios are the worst seed's;
# flagged = status other than `used` in the forward gnss_residuals.txt, or
# refused before weighing, and the same in the smoothed run's file, after
# the smoother's re-judgement; see bed.py) and keeps the per-seed rows in
# $W/rows.txt; then the faulty fixes flagged by class, and each seed's
# forward figures.
#
# Usage (from the repository root): scripts/integrity/table.sh
# QUICK=1: one fault seed per bed instead of five (~45 s instead of
# ~2.5–3.5 min on 2 shared cores); VERBOSE=1: each row as it is measured;
# FAULT_SEEDS="1 2 3": the fault seeds; BEDS="d2-adis16465 drive-icm20602":
# the beds; EXTRA="--nhc": more fuse options for every run; KEEP=1: keep
# every run's navresult.nav, std.txt, imu_err.txt (~2.4 GB for the full set;
# without it ~215 MB: the simulated inputs, residuals, summaries, scores).
# Needs: cargo build --release; python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${NAVSYNC:-target/release/navsync}
D=../shared/data/kfgins-matlab-dataset2
W=${WORK:-target/integrity}
HERE=scripts/integrity
EXTRA=${EXTRA:-}
VEL=${VEL:---no-gnss-velocity}
if [ "${QUICK:-0}" = 1 ]; then FAULT_SEEDS=${FAULT_SEEDS:-1}; else FAULT_SEEDS=${FAULT_SEEDS:-1 2 3 4 5}; fi
BEDS=${BEDS:-d2-adis16465 d2-icm20602 d2-nav drive-adis16465 drive-icm20602 drive10-adis16465 drive10-icm20602}
mkdir -p "$W"
W=$(cd "$W" && pwd)
rows="$W/rows.txt"
echo "# bed seed clean_f clean_s faulty_f faulty_s oracle_f oracle_s off_f big big_flagged clean_flagged_faulty clean_flagged_clean fixes big_flagged_sm clean_flagged_faulty_sm clean_flagged_clean_sm" > "$rows"
field() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))$2)" "$1"; }
hrms() { "$B" eval --truth "$1" --nav "$2" --json "$2.eval.json" >/dev/null; field "$2.eval.json" "['pos_horizontal_m']['rms']"; }
# fuse CFG OUT WEIGHTING → "forward_rms smoothed_rms"
fuse() {
  "$B" fuse --config "$1" --output "$2" --gnss-weighting "$3" --smooth $VEL $EXTRA >/dev/null 2>"$2.log" \
    || { echo "fuse failed ($2.log):" >&2; tail -3 "$2.log" >&2; exit 1; }
  echo "$(hrms "$truth" "$2/forward/navresult.nav") $(hrms "$truth" "$2/navresult.nav")"
  # The 200 Hz solutions are scored: drop them (~35 MB a run) unless KEEP=1.
  if [ "${KEEP:-0}" != 1 ]; then
    rm -f "$2"/{,forward/}{navresult.nav,std.txt,imu_err.txt}
  fi
}
start=$SECONDS
for bed in $BEDS; do
  grade=${bed#*-}
  sim="$W/$bed"
  rm -rf "$sim"   # this script's own folder: no earlier run's files to move aside
  case $bed in
    d2-*) "$B" simulate --from-nav "$D/truth.nav" --gnss-real "$D/GNSS-POSVEL.txt" \
            --gnss-real-layout matlab --set 'gnss.lever_arm_m=[-0.37,0.008,0.353]' \
            --imu-grade "$grade" --seed 1 --quiet --output "$sim"
          count=4 ;;
    drive-*) "$B" simulate --scenario test-track --duration 600 --imu-grade "$grade" \
            --seed 1 --quiet --output "$sim"
          count=8 ;;
    drive10-*) "$B" simulate --scenario test-track --duration 600 --imu-grade "$grade" \
            --gnss-rate 10 --seed 1 --quiet --output "$sim"
          count=8 ;;
    *) echo "unknown bed $bed" >&2; exit 2 ;;
  esac
  truth="$sim/truth.nav"
  read -r clean_f clean_s < <(fuse "$sim/kf-gins.yaml" "$sim/clean" robust)
  for seed in $FAULT_SEEDS; do
    run="$sim/faults-$seed"
    "$B" faults --gnss "$sim/gnss.txt" --output "$run" --seed "$seed" --count "$count" >/dev/null
    python3 $HERE/bed.py drop "$run/gnss.txt" "$run/faults.txt" "$run/gnss-oracle.txt"
    python3 $HERE/bed.py config "$sim/kf-gins.yaml" "$run/kf-gins.yaml" "$sim/imu.txt" "$run/gnss.txt"
    python3 $HERE/bed.py config "$sim/kf-gins.yaml" "$run/kf-gins-oracle.yaml" "$sim/imu.txt" "$run/gnss-oracle.txt"
    read -r faulty_f faulty_s < <(fuse "$run/kf-gins.yaml" "$run/default" robust)
    read -r oracle_f oracle_s < <(fuse "$run/kf-gins-oracle.yaml" "$run/oracle" robust)
    read -r off_f _ < <(fuse "$run/kf-gins.yaml" "$run/off" off)
    fl=$(python3 $HERE/bed.py flags "$sim/gnss.txt" "$run/faults.txt" \
      "$sim/clean/forward/gnss_residuals.txt" "$run/default/forward/gnss_residuals.txt")
    # The same from the smoothed runs' files (their last pass, after the
    # smoother's re-judgement): flagged, clean flagged, clean flagged clean.
    fl_sm=$(python3 $HERE/bed.py flags "$sim/gnss.txt" "$run/faults.txt" \
      "$sim/clean/gnss_residuals.txt" "$run/default/gnss_residuals.txt" | cut -d' ' -f2-4)
    echo "$bed $seed $clean_f $clean_s $faulty_f $faulty_s $oracle_f $oracle_s $off_f $fl $fl_sm" >> "$rows"
    if [ "${VERBOSE:-0}" = 1 ]; then tail -1 "$rows" >&2; fi
  done
done
python3 $HERE/bed.py table "$rows"
echo
echo "faulty fixes (≥ 0.3 m) flagged, by class (forward / smoothed run):"
python3 $HERE/bed.py classes "$W" $BEDS
echo
echo "per fault seed (forward horizontal RMS, m):"
python3 $HERE/bed.py seeds "$rows"
echo "($(( SECONDS - start )) s; per-seed rows in $rows)"
