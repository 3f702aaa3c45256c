#!/usr/bin/env python3
"""Heading error of an aligned run 10 s after the vehicle first moves, and
the horizontal RMS of the aligned run and of a run initialised from truth
over the same epochs (the aligned run's).

Usage: heading_check.py TRUTH.nav ALIGNED.nav TRUTH_INIT.nav
Prints: first_motion_sow yaw_err_deg_at_+10s rms_aligned_m rms_truth_init_m ratio
"""
import bisect
import math
import sys


def read(path):
    rows = []
    for line in open(path):
        v = line.split()
        if len(v) < 11 or line.startswith("#"):
            continue
        rows.append([float(x) for x in v[1:11]])
    rows.sort()
    return rows


def interp(rows, times, t):
    i = bisect.bisect_left(times, t)
    if i <= 0 or i >= len(rows):
        return None
    a, b = rows[i - 1], rows[i]
    u = (t - a[0]) / (b[0] - a[0])
    out = [a[k] + u * (b[k] - a[k]) for k in range(len(a))]
    # yaw: interpolate across the wrap
    dy = (b[9] - a[9] + 180.0) % 360.0 - 180.0
    out[9] = a[9] + u * dy
    return out


def horiz_err(r, tr):
    lat = math.radians(tr[1])
    rm = 6378137.0
    dn = math.radians(r[1] - tr[1]) * rm
    de = math.radians(r[2] - tr[2]) * rm * math.cos(lat)
    return math.hypot(dn, de)


truth, aligned, ref = (read(p) for p in sys.argv[1:4])
tt = [r[0] for r in truth]
moving = next(r[0] for r in truth if math.hypot(r[4], r[5]) > 0.5)
at = interp(truth, tt, moving + 10.0)
ta = [r[0] for r in aligned]
a10 = interp(aligned, ta, moving + 10.0)
yaw_err = (a10[9] - at[9] + 180.0) % 360.0 - 180.0 if a10 and at else float("nan")
start = aligned[0][0]
sq_a, sq_r, n = 0.0, 0.0, 0
ref_t = {round(r[0], 4): r for r in ref}
for r in aligned:
    tr = interp(truth, tt, r[0])
    rr = ref_t.get(round(r[0], 4))
    if tr is None or rr is None:
        continue
    sq_a += horiz_err(r, tr) ** 2
    sq_r += horiz_err(rr, tr) ** 2
    n += 1
ra, rr = math.sqrt(sq_a / n), math.sqrt(sq_r / n)
print(f"{moving:.3f} {yaw_err:+.3f} {ra:.4f} {rr:.4f} {ra / rr:.3f}")
