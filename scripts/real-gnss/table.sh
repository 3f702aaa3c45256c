#!/usr/bin/env bash
# Real trajectory + real GNSS: an exact IMU simulated along the shared
# KF-GINS-Matlab dataset2 reference drive, with the drive's real GNSS fixes
# replayed against it (their real errors and stated σ), fused with each GNSS
# weighting. Prints horizontal RMS (m) without outages and the RMS of the
# per-outage maximum horizontal drift (m) with 30 s outages every 120 s.
#
# Usage (from the repository root): scripts/real-gnss/table.sh [SEED...]
# EXTRA="--nhc": more fuse options for every run (docs/real-gnss.md's land-
# vehicle table); WEIGHTINGS="robust off": the weightings to run;
# GRADES="icm20602": the simulated IMUs; SIM_EXTRA="--set …": more
# simulate options (another IMU error model). Two oracles may be named
# among the weightings: oracle-drop (fixes whose true error exceeds 0.3 m
# left out) and oracle-inflate (each fix's σ raised to its true error),
# both fused with `off`; see oracle_fixes.py.
# Needs: cargo build --release; python3 (for the JSON fields).
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${NAVSYNC:-target/release/navsync}
D=../shared/data/kfgins-matlab-dataset2
W=${WORK:-target/real-gnss}
SEEDS=${*:-1}
VEL=${VEL:---no-gnss-velocity}
EXTRA=${EXTRA:-}
WEIGHTINGS=${WEIGHTINGS:-robust off gate}
GRADES=${GRADES:-adis16465 icm20602 nav}
SIM_EXTRA=${SIM_EXTRA:-}
mkdir -p "$W"
field() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))$2)" "$1"; }
hrms() { "$B" eval --truth "$1/truth.nav" --nav "$2/navresult.nav" --json "$2/eval.json" >/dev/null; field "$2/eval.json" "$3"; }
printf "%-10s %-5s %-14s %10s %10s %6s %6s\n" imu seed weighting horiz_rms outage_rms downw rej
for grade in $GRADES; do
  for seed in $SEEDS; do
    sim="$W/$grade-$seed"
    "$B" simulate --from-nav "$D/truth.nav" --gnss-real "$D/GNSS-POSVEL.txt" \
      --gnss-real-layout matlab --set 'gnss.lever_arm_m=[-0.37,0.008,0.353]' \
      --gnss-velocity --imu-grade "$grade" --seed "$seed" --quiet --output "$sim" $SIM_EXTRA
    case " $WEIGHTINGS " in *" oracle-"*) python3 scripts/real-gnss/oracle_fixes.py "$sim" >/dev/null ;; esac
    for wt in $WEIGHTINGS; do
      out="$sim/$wt"
      cfg="$sim/kf-gins.yaml" fusewt=$wt
      case $wt in oracle-*) cfg="$sim/kf-gins-${wt#oracle-}.yaml" fusewt=off ;; esac
      "$B" fuse --config "$cfg" --output "$out" --gnss-weighting "$fusewt" $VEL $EXTRA >/dev/null 2>&1
      h=$(hrms "$sim" "$out" "['pos_horizontal_m']['rms']")
      dw=$(field "$out/summary.json" "['stats']['gnss_fixes_downweighted']")
      rj=$(field "$out/summary.json" "['stats']['gnss_fixes_rejected']")
      "$B" fuse --config "$cfg" --output "$out-outage" --gnss-weighting "$fusewt" $VEL $EXTRA \
        --outage-period 120 --outage-len 30 --outage-first 60 >/dev/null 2>&1
      o=$(field "$out-outage/summary.json" "['outages']")
      "$B" eval --truth "$sim/truth.nav" --nav "$out-outage/navresult.nav" --outages "$o" \
        --json "$out-outage/eval.json" >/dev/null
      d=$(field "$out-outage/eval.json" "['outage_rms_max_horizontal_m']")
      printf "%-10s %-5s %-14s %10.3f %10.3f %6s %6s\n" "$grade" "$seed" "$wt" "$h" "$d" "$dw" "$rj"
    done
  done
done
