#!/usr/bin/env python3
"""Misleading forward solutions on the integrity bed: the fix epochs whose
horizontal error (against the bed's truth) passes the horizontal protection
level written for them (gnss_residuals.txt's last column), per bed, for the
runs with faults and the clean run, with the worst error / HPL ratio.

Needs a bed run with its solutions kept (from the repository root):

    cargo build --release
    KEEP=1 WORK=target/integrity-keep scripts/integrity/table.sh
    python3 scripts/integrity/misleading.py target/integrity-keep

Python 3 standard library only.
"""
import math
import os
import sys

EARTH_M = 6378137.0


def positions(path):
    """sow (ms) → (lat, lon) of an 11-column nav file."""
    out = {}
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            fields = line.split()
            out[round(float(fields[1]) * 1000)] = (float(fields[2]), float(fields[3]))
    return out


def misleading(truth, run):
    """(epochs, misleading, worst error/HPL) of one forward run folder."""
    nav = positions(os.path.join(run, "navresult.nav"))
    epochs = bad = 0
    worst = 0.0
    with open(os.path.join(run, "gnss_residuals.txt")) as f:
        for line in f:
            fields = line.split()
            if line.startswith("#") or len(fields) < 15 or fields[1] != "position":
                continue
            key = round(float(fields[0]) * 1000)
            if key not in nav or key not in truth:
                continue
            (lat, lon), (tlat, tlon) = nav[key], truth[key]
            dn = math.radians(lat - tlat) * EARTH_M
            de = math.radians(lon - tlon) * EARTH_M * math.cos(math.radians(tlat))
            error, hpl = math.hypot(dn, de), float(fields[14])
            epochs += 1
            bad += error > hpl
            worst = max(worst, error / max(hpl, 1e-9))
    return epochs, bad, worst


def forward_dir(run):
    """The forward files of a `fuse --smooth` run, else the run's own."""
    fwd = os.path.join(run, "forward")
    return fwd if os.path.isdir(fwd) else run


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    work = sys.argv[1]
    print("| bed | with faults: misleading fix epochs | worst error / HPL | clean: misleading | worst |")
    print("|---|---|---|---|---|")
    for bed in sorted(os.listdir(work)):
        truth_path = os.path.join(work, bed, "truth.nav")
        if not os.path.isfile(truth_path):
            continue
        truth = positions(truth_path)
        faulty = [0, 0, 0.0]
        seeds = sorted(d for d in os.listdir(os.path.join(work, bed)) if d.startswith("faults-"))
        for seed in seeds:
            run = forward_dir(os.path.join(work, bed, seed, "default"))
            if not os.path.isfile(os.path.join(run, "navresult.nav")):
                sys.exit(f"{run}: no navresult.nav (run the bed with KEEP=1)")
            e, b, w = misleading(truth, run)
            faulty = [faulty[0] + e, faulty[1] + b, max(faulty[2], w)]
        e, b, w = misleading(truth, forward_dir(os.path.join(work, bed, "clean")))
        print(
            f"| {bed} ({len(seeds)} seeds) | {100 * faulty[1] / max(faulty[0], 1):.2f} % of {faulty[0]} "
            f"| {faulty[2]:.1f} | {100 * b / max(e, 1):.2f} % of {e} | {w:.2f} |"
        )


if __name__ == "__main__":
    main()
