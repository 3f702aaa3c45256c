#!/usr/bin/env python3
"""The real-logs table of docs/real-logs.md: `navsync process` on every real
log in ../shared/data/real-logs (and any more given as NAME=PATH), then, for
each run, the forward and smoothed horizontal RMS against the log's own
fixes, the heading (the IMU's yaw less the run's mounting yaw) against the GNSS
course (land vehicles), the mounting yaw found in the motion and the one
used, and the verdict.

Python 3 standard library only (no numpy). From the repository root:

    cargo build --release
    python3 scripts/real-logs/table.py [--out /tmp/real-logs] [NAME=PATH ...]

The fixes are the log's own (no reference trajectory exists): the RMS
against them measures how closely a solution follows them, not its
accuracy. The heading against the course uses chords of the track at least
3 m long over at most 5 s: a vehicle that moves sideways (a multicopter)
has no such relation, and its row says so.
"""

import json
import math
import os
import re
import subprocess
import sys

NAVSYNC = os.environ.get("NAVSYNC", "target/release/navsync")
SHARED = "../shared/data/real-logs"
DEFAULT_LOGS = [
    ("Husky ROS 1 bag", f"{SHARED}/husky-ros1-bag/test1.bag", "land"),
    ("ArduCopter DataFlash", f"{SHARED}/ardupilot-copter-dataflash/16.BIN", "air"),
]
R_EARTH = 6378137.0


def read_rows(path, min_cols):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            v = [float(x) for x in re.split(r"[,\s]+", line) if x]
            if len(v) >= min_cols:
                rows.append(v)
    return rows


def interp(ts, vals, t):
    """Linear interpolation of vals (list of tuples) at t; None outside."""
    lo, hi = 0, len(ts) - 1
    if not ts or t < ts[0] or t > ts[-1]:
        return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ts[mid] <= t:
            lo = mid
        else:
            hi = mid
    t0, t1 = ts[lo], ts[hi]
    u = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
    return tuple(a + u * (b - a) for a, b in zip(vals[lo], vals[hi]))


def rms_vs_fixes(nav, fixes):
    lat0 = math.radians(fixes[0][1])
    ts = [r[1] for r in nav]
    ll = [(r[2], r[3]) for r in nav]
    s, n = 0.0, 0
    for f in fixes:
        p = interp(ts, ll, f[0])
        if p is None:
            continue
        dn = math.radians(p[0] - f[1]) * R_EARTH
        de = math.radians(p[1] - f[2]) * R_EARTH * math.cos(lat0)
        s += dn * dn + de * de
        n += 1
    return (math.sqrt(s / n) if n else float("nan")), n


def heading_vs_course(nav, fixes, mount_yaw_deg=0.0):
    """Median and spread (deg) of heading − course over chords ≥ 3 m, ≤ 5 s;
    the heading is the IMU's yaw less the run's mounting yaw."""
    lat0 = math.radians(fixes[0][1])
    ne = [(math.radians(f[1]) * R_EARTH, math.radians(f[2]) * R_EARTH * math.cos(lat0)) for f in fixes]
    ts = [r[1] for r in nav]
    yaws = [(math.cos(math.radians(r[10])), math.sin(math.radians(r[10]))) for r in nav]
    d = []
    j = 0
    for i in range(len(fixes)):
        while j < len(fixes) and fixes[j][0] < fixes[i][0] + 5.0:
            j += 1
        if j >= len(fixes):
            break
        dn, de = ne[j][0] - ne[i][0], ne[j][1] - ne[i][1]
        if math.hypot(dn, de) < 3.0:
            continue
        c = interp(ts, yaws, 0.5 * (fixes[i][0] + fixes[j][0]))
        if c is None:
            continue
        yaw = math.atan2(c[1], c[0])
        x = math.degrees(yaw - math.atan2(de, dn)) - mount_yaw_deg
        d.append((x + 180.0) % 360.0 - 180.0)
    if not d:
        return None
    d.sort()
    med = d[len(d) // 2]
    spread = math.sqrt(sum(((x - med + 180) % 360 - 180) ** 2 for x in d) / len(d))
    return med, spread, len(d)


def mount_words(m):
    """The mounting yaw found in the motion and the one the run used."""
    if not m:
        return "not searched"
    e = m["estimate"]
    found = "no samples" if e["yaw_deg"] is None else f"{e['yaw_deg']:.1f}° ± {e['sd_deg']:.1f}°"
    if not e["observable"]:
        found += " (not observable)"
    return f"{found} → {m['used_yaw_deg']:.1f}°"


def verdict(report_html):
    try:
        text = open(report_html).read()
    except OSError:
        return "no report"
    m = re.search(r'"grade":"([a-z-]+)","checks"', text)
    return m.group(1) if m else "?"


def run(name, path, kind, out_root):
    out = os.path.join(out_root, re.sub(r"\W+", "-", name.lower()).strip("-"))
    sheet = os.path.join(out_root, "sheet.yaml")
    if not os.path.exists(sheet):
        subprocess.run([NAVSYNC, "init", "--output", sheet], check=True, capture_output=True)
    p = subprocess.run(
        [NAVSYNC, "process", path, "--sensor", sheet, "--output", out],
        capture_output=True,
        text=True,
    )
    row = {"log": name, "file": path, "exit": p.returncode}
    if p.returncode != 0:
        row["error"] = (p.stderr.strip().splitlines() or ["?"])[-1]
        return row
    pj = json.load(open(os.path.join(out, "process.json")))
    fixes = read_rows(pj["gnss"], 7)
    smoothed = read_rows(os.path.join(out, "fuse", "navresult.nav"), 11)
    fwd_path = os.path.join(out, "fuse", "forward", "navresult.nav")
    forward = read_rows(fwd_path, 11) if os.path.exists(fwd_path) else None
    row["duration_s"] = round(fixes[-1][0] - fixes[0][0], 1)
    row["fixes"] = len(fixes)
    row["imu_rate_hz"] = round(pj.get("imu_rate_hz", float("nan")), 1)
    row["smoothed_rms_m"], n = rms_vs_fixes(smoothed, fixes)
    row["coverage"] = n / len(fixes)
    row["week"] = int(smoothed[0][0])
    if forward:
        row["forward_rms_m"], _ = rms_vs_fixes(forward, fixes)
    summary = json.load(open(os.path.join(out, "fuse", "summary.json")))
    m = summary.get("mount_yaw")
    row["mount_yaw"] = m
    if kind == "land":
        h = heading_vs_course(smoothed, fixes, m["used_yaw_deg"] if m else 0.0)
        row["heading_minus_course_deg"] = None if h is None else (round(h[0], 1), round(h[1], 1), h[2])
    row["verdict"] = verdict(os.path.join(out, "report.html"))
    return row


def main(argv):
    out_root = "/tmp/navsync-real-logs"
    logs = list(DEFAULT_LOGS)
    args = list(argv)
    if args[:1] == ["--out"]:
        out_root, args = args[1], args[2:]
    for a in args:
        name, _, path = a.partition("=")
        logs.append((name, path, "land"))
    os.makedirs(out_root, exist_ok=True)
    print("| log | duration | fixes | IMU | forward RMS vs fixes | smoothed RMS vs fixes | coverage | heading − course (median, spread, chords) | mount yaw: motion → used | week | verdict |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, path, kind in logs:
        r = run(name, path, kind, out_root)
        if "error" in r:
            print(f"| {name} | – | – | – | – | – | – | – | – | – | exit {r['exit']}: {r['error']} |")
            continue
        h = r.get("heading_minus_course_deg")
        hs = "not a land vehicle" if kind != "land" else ("no chords" if h is None else f"{h[0]}°, {h[1]}°, {h[2]}")
        fwd = r.get("forward_rms_m")
        print(
            f"| {name} | {r['duration_s']} s | {r['fixes']} | {r['imu_rate_hz']} Hz | "
            f"{'–' if fwd is None else f'{fwd:.2f} m'} | {r['smoothed_rms_m']:.2f} m | "
            f"{100 * r['coverage']:.1f} % | {hs} | {mount_words(r.get('mount_yaw'))} | {r['week']} | {r['verdict']} |"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
