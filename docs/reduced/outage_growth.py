#!/usr/bin/env python3
"""Horizontal error growth inside each outage: max |e(t) - e(t_start)| over the
outage, e = solution - truth (N, E), truth interpolated linearly. Removes the
error present when the outage starts (e.g. a GNSS bias against the reference).
Usage: outage_growth.py TRUTH.nav RUN_DIR [RUN_DIR...] (outages from summary.json)."""
import sys, json, os
import numpy as np

tr = np.loadtxt(sys.argv[1])
for run in sys.argv[2:]:
    s = json.load(open(os.path.join(run, "summary.json")))
    nav = np.loadtxt(os.path.join(run, "navresult.nav"))
    lat = np.interp(nav[:, 1], tr[:, 1], tr[:, 2])
    lon = np.interp(nav[:, 1], tr[:, 1], tr[:, 3])
    en = (nav[:, 2] - lat) * 111_320.0
    ee = (nav[:, 3] - lon) * 111_320.0 * np.cos(np.radians(lat))
    out = []
    for w in filter(None, s["outages"].split(",")):
        t0, ln = map(float, w.split(":"))
        m = (nav[:, 1] >= t0) & (nav[:, 1] <= t0 + ln)
        if not m.any():
            continue
        i0 = np.argmax(m)
        g = np.hypot(en[m] - en[i0], ee[m] - ee[i0])
        out.append(g.max())
    rms = np.sqrt(np.mean(np.square(out))) if out else float("nan")
    print(f"{os.path.basename(run.rstrip('/'))}: growth per outage " + ", ".join(f"{x:.2f}" for x in out) + f" m; RMS {rms:.2f} m")
