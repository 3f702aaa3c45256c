#!/usr/bin/env python3
"""Helpers of scripts/integrity/table.sh (python3 standard library only).

  config SRC OUT IMU GNSS      a KF-GINS configuration SRC with imupath and
                               gnsspath replaced (absolute paths) → OUT
  drop GNSS LABELS OUT         GNSS without the labelled fixes (the oracle)
  flags GNSS LABELS CLEAN FAULTY
                               one line: labelled fixes with a fault ≥ 0.3 m,
                               how many of them were flagged in FAULTY, clean
                               fixes flagged in FAULTY, the same fixes flagged
                               in CLEAN, all fixes (CLEAN and FAULTY are
                               gnss_residuals.txt files)
  table ROWS                   the bed table from the rows table.sh wrote
  seeds ROWS                   per bed and fault seed: forward clean, faults
                               default, oracle, KF-GINS rule
  classes W BED...             per bed and class: faulty fixes (≥ 0.3 m)
                               flagged by the default run, forward / smoothed
                               (its last pass, after the smoother's
                               re-judgement), pooled over the fault seeds
                               found in W/BED/faults-*

A fix is flagged when its position line in gnss_residuals.txt (docs/FORMATS.md:
`sow kind innov_n innov_e innov_d sd_n sd_e sd_d nis w_n w_e w_d status reason hpl_m`)
has a status other than `used`, or when it has no line at all (refused before
weighing: a stale repeat, an invalid fix).
"""
import math
import sys

BIG_M = 0.3  # faults below this are beneath what any test can see (issue 33)


def records(path):
    """(key, line) of each record line: key = sow rounded to the ms."""
    out = []
    with open(path) as f:
        for line in f:
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            out.append((key(s.replace(",", " ").split()[0]), line))
    return out


def key(sow_text):
    return round(float(sow_text) * 1000)


def labels(path):
    """{key: (class, norm of the offset in m)}."""
    out = {}
    for k, line in records(path):
        f = line.split()
        out[k] = (f[1], math.sqrt(sum(float(x) ** 2 for x in f[3:6])))
    return out


def statuses(path):
    """{key: status} of the position lines of a gnss_residuals.txt."""
    out = {}
    for k, line in records(path):
        f = line.split()
        if f[1] == "position":
            # The 13th field (reason and protection level follow it).
            out[k] = f[12]
    return out


def config(src, out, imu, gnss):
    with open(src) as f, open(out, "w") as g:
        for line in f:
            if line.startswith("imupath:"):
                line = f'imupath: "{imu}"\n'
            elif line.startswith("gnsspath:"):
                line = f'gnsspath: "{gnss}"\n'
            g.write(line)


def drop(gnss, lab, out):
    bad = labels(lab)
    with open(gnss) as f, open(out, "w") as g:
        for line in f:
            s = line.strip()
            if s and not s.startswith("#") and key(s.replace(",", " ").split()[0]) in bad:
                continue
            g.write(line)


def flags(gnss, lab, clean, faulty):
    bad = labels(lab)
    fixes = [k for k, _ in records(gnss)]
    sc, sf = statuses(clean), statuses(faulty)
    flagged = lambda st, k: st.get(k, "refused") != "used"
    big = [k for k, (_, size) in bad.items() if size >= BIG_M]
    big_flagged = sum(flagged(sf, k) for k in big)
    good = [k for k in fixes if k not in bad]
    print(len(big), big_flagged, sum(flagged(sf, k) for k in good), sum(flagged(sc, k) for k in good), len(fixes))


def table(rows_path):
    beds = {}
    for line in open(rows_path):
        if line.startswith("#") or not line.strip():
            continue
        f = line.split()
        beds.setdefault(f[0], []).append([float(x) for x in f[2:]])
    head = ("bed", "clean", "faults default", "oracle", "def/oracle", "KF-GINS rule + faults",
            "faulty flagged", "clean extra flagged", "smoothed faults", "smoothed oracle", "sm/(sm oracle+3cm)",
            "flagged, smoothed run", "clean extra, smoothed run")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for bed, rows in beds.items():
        mean = lambda i: sum(r[i] for r in rows) / len(rows)
        worst = lambda f: max(f(r) for r in rows)
        # row: clean_f clean_s faulty_f faulty_s oracle_f oracle_s off_f big big_flagged
        #      clean_flagged_faulty clean_flagged_clean fixes, then the smoothed run's
        #      big_flagged clean_flagged_faulty clean_flagged_clean
        big = sum(r[7] for r in rows)
        fixes = sum(r[11] for r in rows)
        pct = lambda i: 100.0 * sum(r[i] for r in rows) / big if big else float("nan")
        extra = lambda i: 100.0 * sum(r[i] - r[i + 1] for r in rows) / fixes
        print(f"| {bed} ({len(rows)} seed{'s' if len(rows) > 1 else ''}) | {mean(0):.3f} m | **{mean(2):.3f} m** | {mean(4):.3f} m "
              f"| {worst(lambda r: r[2] / r[4]):.2f} | {mean(6):.3f} m | {pct(8):.0f} % of {big:.0f} | {extra(9):+.1f} % "
              f"| {mean(3):.3f} m | {mean(5):.3f} m | {worst(lambda r: r[3] / (r[5] + 0.03)):.2f} "
              f"| {pct(12):.0f} % | {extra(13):+.1f} % |")


def seeds(rows_path):
    print("| bed | seed | clean | faults default | oracle | def/oracle | KF-GINS rule + faults |")
    print("|---|---|---|---|---|---|---|")
    for line in open(rows_path):
        if line.startswith("#") or not line.strip():
            continue
        f = line.split()
        r = [float(x) for x in f[2:]]
        print(f"| {f[0]} | {f[1]} | {r[0]:.3f} | {r[2]:.3f} | {r[4]:.3f} | {r[2] / r[4]:.2f} | {r[6]:.3f} |")


def classes(work, *beds):
    import glob
    import os
    names = ("spike", "false-fix", "ramp", "stale")
    print("| bed | " + " | ".join(names) + " |")
    print("|" + "---|" * (len(names) + 1))
    for bed in beds:
        got = {c: [0, 0, 0] for c in names}
        for run in sorted(glob.glob(os.path.join(work, bed, "faults-*"))):
            st = statuses(os.path.join(run, "default", "forward", "gnss_residuals.txt"))
            st_sm = statuses(os.path.join(run, "default", "gnss_residuals.txt"))
            for k, (c, size) in labels(os.path.join(run, "faults.txt")).items():
                if size >= BIG_M:
                    got[c][0] += st.get(k, "refused") != "used"
                    got[c][1] += st_sm.get(k, "refused") != "used"
                    got[c][2] += 1
        cell = lambda f, f_sm, n: f"{100.0 * f / n:.0f} / {100.0 * f_sm / n:.0f} % of {n}" if n else "–"
        print(f"| {bed} | " + " | ".join(cell(*got[c]) for c in names) + " |")


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    {"config": config, "drop": drop, "flags": flags, "table": table, "seeds": seeds, "classes": classes}[cmd](*args)
