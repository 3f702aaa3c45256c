#!/usr/bin/env python3
"""Misleading solutions on the integrity bed: the fix epochs whose
horizontal error (against the bed's truth) passes the horizontal protection
level written for them, per bed, for the runs with faults and the clean
run, with the worst error / HPL ratio. A fix is judged at the epoch that
fuses it: the first solution epoch at or after its time (the one before it
is the prediction the fix corrects). Forward: gnss_residuals.txt's last
column (K σ, K = 6, after the fix). Smoothed: K √(σ_N² + σ_E²) of the
smoothed std.txt line at or after that epoch (std.txt has no N–E
covariance; the root sum is the largest the major axis can be).

A second table gives the clean runs' σ against their error: the mean of
e²/(σ_N² + σ_E²) over the fix epochs (horizontal NEES per degree of
freedom, 1 where the σ are right, above where they are optimistic),
forward and smoothed, each std.txt line against the error at its own time.

Needs a bed run with its solutions kept (from the repository root):

    cargo build --release
    KEEP=1 WORK=target/integrity-keep scripts/integrity/table.sh
    python3 scripts/integrity/misleading.py target/integrity-keep

Python 3 standard library only.
"""
import bisect
import math
import os
import sys

PROTECTION_K = 6.0

EARTH_M = 6378137.0


def positions(path):
    """(sorted sow list, sow (ms) → (lat, lon)) of an 11-column nav file."""
    times, out = [], {}
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            fields = line.split()
            times.append(float(fields[1]))
            out[round(times[-1] * 1000)] = (float(fields[2]), float(fields[3]))
    times.sort()
    return times, out


def at_or_after(times, sow):
    """Index of the first of the sorted `times` at or after `sow` (1 µs
    tolerance), clamped to the last."""
    return min(bisect.bisect_left(times, sow - 1e-6), len(times) - 1)


def std_horizontal(run):
    """sow → (line time, √(σ_N² + σ_E²)) of the first std.txt line at or
    after it."""
    times, sds = [], []
    with open(os.path.join(run, "std.txt")) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            fields = line.split()
            times.append(float(fields[0]))
            sds.append(math.hypot(float(fields[1]), float(fields[2])))

    def at(sow):
        i = at_or_after(times, sow)
        return times[i], sds[i]

    return at


def horizontal_error(nav, truth, sow):
    """Horizontal error (m) of the solution at `sow`, or None where the
    solution or the truth has no record then."""
    key = round(sow * 1000)
    if key not in nav or key not in truth:
        return None
    (lat, lon), (tlat, tlon) = nav[key], truth[key]
    dn = math.radians(lat - tlat) * EARTH_M
    de = math.radians(lon - tlon) * EARTH_M * math.cos(math.radians(tlat))
    return math.hypot(dn, de)


def fix_epochs(truth, run, solution):
    """(epoch sow, horizontal error m, gnss_residuals fields) of the run's
    position fixes, each at the epoch of `solution` (the run's
    `positions`) that fuses it."""
    times, nav = solution
    with open(os.path.join(run, "gnss_residuals.txt")) as f:
        for line in f:
            fields = line.split()
            if line.startswith("#") or len(fields) < 15 or fields[1] != "position":
                continue
            epoch = times[at_or_after(times, float(fields[0]))]
            error = horizontal_error(nav, truth, epoch)
            if error is not None:
                yield epoch, error, fields


def nees_per_dof(truth, run):
    """Mean e²/(σ_N² + σ_E²) over the run's fix epochs: each fix's first
    std.txt line against the error at that line's time."""
    sd = std_horizontal(run)
    solution = positions(os.path.join(run, "navresult.nav"))
    _, nav = solution
    values = []
    for epoch, _, _ in fix_epochs(truth, run, solution):
        when, sigma = sd(epoch)
        error = horizontal_error(nav, truth, when)
        if error is not None:
            values.append((error / max(sigma, 1e-9)) ** 2)
    return sum(values) / max(len(values), 1)


def misleading(truth, run, smoothed=False):
    """(epochs, misleading, worst error/HPL) of one run folder: the
    forward's HPL from gnss_residuals.txt, the smoothed's from std.txt."""
    sd = std_horizontal(run) if smoothed else None
    epochs = bad = 0
    worst = 0.0
    solution = positions(os.path.join(run, "navresult.nav"))
    for epoch, error, fields in fix_epochs(truth, run, solution):
        hpl = PROTECTION_K * sd(epoch)[1] if smoothed else float(fields[14])
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
    print(
        "| bed | forward with faults: misleading fix epochs | worst error / HPL | clean | worst "
        "| smoothed with faults | worst | clean | worst |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    beds = []
    for bed in sorted(os.listdir(work)):
        truth_path = os.path.join(work, bed, "truth.nav")
        if not os.path.isfile(truth_path):
            continue
        _, truth = positions(truth_path)
        seeds = sorted(d for d in os.listdir(os.path.join(work, bed)) if d.startswith("faults-"))
        cells = []
        for smoothed in (False, True):
            faulty = [0, 0, 0.0]
            for seed in seeds:
                run = os.path.join(work, bed, seed, "default")
                run = run if smoothed else forward_dir(run)
                if not os.path.isfile(os.path.join(run, "navresult.nav")):
                    sys.exit(f"{run}: no navresult.nav (run the bed with KEEP=1)")
                e, b, w = misleading(truth, run, smoothed)
                faulty = [faulty[0] + e, faulty[1] + b, max(faulty[2], w)]
            clean = os.path.join(work, bed, "clean")
            e, b, w = misleading(truth, clean if smoothed else forward_dir(clean), smoothed)
            cells += [
                f"{100 * faulty[1] / max(faulty[0], 1):.2f} % of {faulty[0]}",
                f"{faulty[2]:.1f}",
                f"{100 * b / max(e, 1):.2f} %",
                f"{w:.2f}",
            ]
        print(f"| {bed} ({len(seeds)} seeds) | " + " | ".join(cells) + " |")
        beds.append((bed, truth))
    print()
    print("| bed | clean run, forward: mean e²/(σ_N² + σ_E²) | smoothed |")
    print("|---|---|---|")
    for bed, truth in beds:
        clean = os.path.join(work, bed, "clean")
        print(f"| {bed} | {nees_per_dof(truth, forward_dir(clean)):.2f} | {nees_per_dof(truth, clean):.2f} |")


if __name__ == "__main__":
    main()
