#!/usr/bin/env python3
"""The verdict's labelled bed; run through calibrate.sh (it sets the
environment: NAVSYNC, WORK, SEEDS, SCENARIOS, GRADES, DURATION, JOBS).

Each drive (scenario × IMU grade × seed) is simulated once clean and once per
data defect (GNSS tags late, GNSS σ misstated); each is processed with the
right sensor sheet and with each sheet defect, as a user would
(`navsync process rig.csv --sensor sheet.yaml`, no truth). The truth then
measures the horizontal RMS; the loss is that RMS over the clean run's.
Labels: clean; defect with loss ≤ 2×, in (2×, 5×], > 5×.
"""
import concurrent.futures as cf
import csv
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

B = os.environ["NAVSYNC"]
W = Path(os.environ["WORK"])
SEEDS = os.environ["SEEDS"].split()
SCENARIOS = os.environ["SCENARIOS"].split()
GRADES = os.environ["GRADES"].split()
DURATION = os.environ["DURATION"]
JOBS = int(os.environ["JOBS"])
KEEP = os.environ.get("KEEP", "") not in ("", "0")

# The simulator's antenna (navsync-sim GnssSpec default), FRD metres.
LEVER = [0.1, 0.5, -1.2]
# A better IMU's figures than the data's, and a sheet for another IMU.
BETTER = {"adis16465": "tactical", "icm20602": "adis16465", "nav": None}
OTHER = {"adis16465": "icm20602", "icm20602": "nav", "nav": "icm20602"}
# Data defects: (name, extra simulate arguments as a function of the clean σ).
TIME_OFFSETS_S = [0.01, 0.03]
SIGMA_SCALES = [0.2, 5.0]


def run(cmd, log=None):
    with open(log, "w") if log else open(os.devnull, "w") as out:
        return subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT).returncode


def simulate(out, scenario, grade, seed, extra=()):
    if not (out / "rig.csv").exists():
        rc = run([B, "simulate", "--quiet", "--internal-rate", "0", "--scenario", scenario,
                  "--duration", DURATION, "--imu-grade", grade, "--seed", seed,
                  "--output", str(out), *extra])
        if rc != 0:
            sys.exit(f"simulate failed: {out}")


def sheet(path, preset, lever=LEVER, mount=None, rate=None, scale_noise=None):
    run([B, "init", "--preset", preset, "--output", str(path), "--force"])
    text = path.read_text()
    text = re.sub(r"(?m)^antenna_lever_m: .*$", f"antenna_lever_m: {lever}", text)
    if mount is not None:
        text = re.sub(r"(?m)^mount_deg: .*$", f"mount_deg: {mount}", text)
    if rate is not None:
        text = re.sub(r"(?m)^  # rate_hz: .*$", f"  rate_hz: {rate}", text)
    if scale_noise is not None:
        def scaled(m):
            return f"{m.group(1)}{float(m.group(2)) * scale_noise}"
        text = re.sub(r"(?m)^(  (?:arw_deg_sqrt_h|vrw_mps_sqrt_h|gyro_bias_instability_deg_h|"
                      r"accel_bias_instability_mgal): )([0-9.eE+-]+)$", scaled, text)
    path.write_text(text)


def verdict_of(html):
    m = re.search(r'<script type="application/json" id="navsync-verdict">(.*?)</script>',
                  html.read_text(), re.S)
    return json.loads(m.group(1)) if m else None


def hrms(truth, nav, js):
    if run([B, "eval", "--truth", str(truth), "--nav", str(nav), "--json", str(js)]) != 0:
        return float("nan")
    return json.loads(js.read_text())["pos_horizontal_m"]["rms"]


def process(job):
    sim, sheet_path, out = job
    rc = run([B, "process", str(sim / "rig.csv"), "--sensor", str(sheet_path),
              "--output", str(out), "--force"], out.with_suffix(".log"))
    if rc != 0 or not (out / "report.html").exists():
        return {"verdict": "failed", "hrms": float("nan"), "reasons": "process exit %d" % rc}
    v = verdict_of(out / "report.html")
    h = hrms(sim / "truth.nav", out / "fuse" / "navresult.nav", out / "eval.json")
    if not KEEP:  # a run's files are ~30 MB; keep the page and the log
        for sub in ("fuse", "sync", ".previous"):
            shutil.rmtree(out / sub, ignore_errors=True)
    bad = [c for c in v["checks"] if c.get("grade") not in (None, "good")]
    return {"verdict": v["grade"], "hrms": h,
            "reasons": "; ".join(f"{c['name']}={c['grade']}" for c in bad),
            "cause": v.get("cause", "")}


def main():
    W.mkdir(parents=True, exist_ok=True)
    jobs = []  # (drive, defect, sim dir, sheet, out dir)
    for scenario in SCENARIOS:
        for grade in GRADES:
            for seed in SEEDS:
                d = W / f"{scenario}-{grade}-{seed}"
                d.mkdir(exist_ok=True)
                clean = d / "sim"
                simulate(clean, scenario, grade, seed)
                sd = json.loads((clean / "scenario.json").read_text())["gnss_resolved"]["std_written_m"]
                sims = {"clean": clean}
                for dt in TIME_OFFSETS_S:
                    s = d / f"sim-offset{dt * 1e3:.0f}ms"
                    simulate(s, scenario, grade, seed, ["--set", f"gnss.time_offset_s={dt}"])
                    sims[f"GNSS tags {dt * 1e3:.0f} ms late"] = s
                for k in SIGMA_SCALES:
                    s = d / f"sim-sigma{k}"
                    v = ",".join(f"{x * k:.6f}" for x in sd)
                    simulate(s, scenario, grade, seed, ["--set", f"gnss.std_written_m=[{v}]"])
                    sims[f"GNSS σ stated ×{k}"] = s
                sheets = {}
                sheet(d / "right.yaml", grade)
                sheets["clean"] = d / "right.yaml"
                sheet(d / "lever0.yaml", grade, lever=[0.0, 0.0, 0.0])
                sheets["lever arm zero"] = d / "lever0.yaml"
                sheet(d / "leverf.yaml", grade, lever=[LEVER[0] + 0.4, LEVER[1], LEVER[2]])
                sheets["lever arm 0.4 m forward"] = d / "leverf.yaml"
                sheet(d / "leverr.yaml", grade, lever=[LEVER[0], LEVER[1] - 0.3, LEVER[2]])
                sheets["lever arm 0.3 m left"] = d / "leverr.yaml"
                sheet(d / "mount.yaml", grade, mount=[0.0, 0.0, 3.0])
                sheets["mounting yaw 3° off"] = d / "mount.yaml"
                sheet(d / "rate.yaml", grade, rate=100)
                sheets["IMU rate 100 Hz in the sheet (data 200 Hz)"] = d / "rate.yaml"
                if BETTER[grade]:
                    sheet(d / "better.yaml", BETTER[grade])
                    sheets[f"{BETTER[grade]} figures (a better IMU)"] = d / "better.yaml"
                else:
                    sheet(d / "better.yaml", grade, scale_noise=0.2)
                    sheets["noise figures ×0.2 (a better IMU)"] = d / "better.yaml"
                sheet(d / "other.yaml", OTHER[grade])
                sheets[f"{OTHER[grade]} sheet"] = d / "other.yaml"
                drive = d.name
                for name, sh in sheets.items():
                    jobs.append((drive, name, clean, sh, d / f"run-{sh.stem}"))
                for name, s in sims.items():
                    if name != "clean":
                        jobs.append((drive, name, s, sheets["clean"], d / f"run-{s.name}"))
    with cf.ThreadPoolExecutor(JOBS) as ex:
        results = list(ex.map(lambda j: process((j[2], j[3], j[4])), jobs))
    rows = []
    clean_rms = {j[0]: r["hrms"] for j, r in zip(jobs, results) if j[1] == "clean"}
    for j, r in zip(jobs, results):
        base = clean_rms.get(j[0], float("nan"))
        loss = r["hrms"] / base if base > 0 else float("nan")
        if j[1] == "clean":
            label = "clean"
        elif not loss == loss:
            label = "defect, failed"
        elif loss > 5:
            label = "defect, loss > 5×"
        elif loss > 2:
            label = "defect, loss 2–5×"
        else:
            label = "defect, loss ≤ 2×"
        rows.append({"drive": j[0], "defect": j[1], "hrms_m": f"{r['hrms']:.4f}",
                     "loss": f"{loss:.2f}", "label": label, "verdict": r["verdict"],
                     "cause": r.get("cause", ""), "reasons": r["reasons"]})
    with open(W / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    labels = ["clean", "defect, loss ≤ 2×", "defect, loss 2–5×", "defect, loss > 5×", "defect, failed"]
    grades = ["good", "caution", "poor", "failed"]
    print(f"{len(rows)} runs ({W / 'runs.csv'})\n")
    print("| label | runs | " + " | ".join(grades) + " |")
    print("|---|---|" + "---|" * len(grades))
    for lab in labels:
        sel = [r for r in rows if r["label"] == lab]
        if sel:
            print(f"| {lab} | {len(sel)} | " + " | ".join(
                str(sum(r["verdict"] == g for r in sel)) for g in grades) + " |")

    print("\nBy defect (loss min … max; verdicts good / caution / poor):\n")
    print("| defect | runs | loss | good / caution / poor |")
    print("|---|---|---|---|")
    for name in dict.fromkeys(r["defect"] for r in rows):
        sel = [r for r in rows if r["defect"] == name]
        ls = sorted(float(r["loss"]) for r in sel)
        print(f"| {name} | {len(sel)} | {ls[0]:.2f} … {ls[-1]:.2f} | "
              + " / ".join(str(sum(r["verdict"] == g for r in sel)) for g in ("good", "caution", "poor")) + " |")

    def rate(sel, ok):
        return f"{sum(map(ok, sel))}/{len(sel)}" + (f" ({100 * sum(map(ok, sel)) / len(sel):.0f} %)" if sel else "")
    clean = [r for r in rows if r["label"] == "clean"]
    big = [r for r in rows if r["label"] in ("defect, loss 2–5×", "defect, loss > 5×")]
    huge = [r for r in rows if r["label"] == "defect, loss > 5×"]
    print(f"\nclean runs good: {rate(clean, lambda r: r['verdict'] == 'good')} (target ≥ 95 %)")
    print(f"loss > 2× not good: {rate(big, lambda r: r['verdict'] != 'good')} (target ≥ 90 %)")
    print(f"loss > 5× poor: {rate(huge, lambda r: r['verdict'] == 'poor')}")
    print("\nmisgraded:")
    for r in rows:
        wrong = ((r["label"] == "clean" and r["verdict"] != "good")
                 or (r["label"] in ("defect, loss 2–5×", "defect, loss > 5×") and r["verdict"] == "good")
                 or (r["label"] == "defect, loss > 5×" and r["verdict"] != "poor"))
        if wrong:
            print(f"  {r['drive']:24} {r['defect']:40} loss {r['loss']:>6} {r['verdict']:8} {r['reasons']}")


if __name__ == "__main__":
    main()
