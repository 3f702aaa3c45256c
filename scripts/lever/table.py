#!/usr/bin/env python3
"""The lever-arm states' table (docs/lever-arm.md): simulated drives with the
antenna at LEVER, each processed as a user would (`navsync process rig.csv
--sensor SHEET`, no truth) with the right sheet, a zero sheet, the zero
sheet with the lever-arm states (`estimate_lever_arm: true`) and the right
sheet with the states; the truth then measures the horizontal RMS. Run
through table.sh (it sets NAVSYNC, WORK, SEEDS, SCENARIOS, GRADES, DURATION).
"""
import json
import os
import re
import subprocess
import sys
from pathlib import Path

B = os.environ["NAVSYNC"]
W = Path(os.environ["WORK"])
SEEDS = os.environ["SEEDS"].split()
SCENARIOS = os.environ["SCENARIOS"].split()
GRADES = os.environ["GRADES"].split()
DURATION = os.environ["DURATION"]
LEVER = [0.4, -0.3, -0.8]
SHEETS = [("right", LEVER, False), ("zero", [0.0, 0.0, 0.0], False),
          ("zero + states", [0.0, 0.0, 0.0], True), ("right + states", LEVER, True)]


def run(cmd, log=None):
    with open(log, "w") if log else open(os.devnull, "w") as out:
        return subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT).returncode


def sheet(path, preset, lever, estimate):
    run([B, "init", "--preset", preset, "--output", str(path), "--force"])
    text = path.read_text()
    line = f"antenna_lever_m: {lever}" + ("\nestimate_lever_arm: true" if estimate else "")
    text = re.sub(r"(?m)^antenna_lever_m: .*$", line, text)
    path.write_text(text)


def verdict_of(html):
    m = re.search(r'<script type="application/json" id="navsync-verdict">(.*?)</script>',
                  html.read_text(), re.S)
    return json.loads(m.group(1)) if m else None


def main():
    W.mkdir(parents=True, exist_ok=True)
    print("| drive | IMU | seed | sheet | horizontal RMS (m) | × right | lever arm estimated ± σ (m) | verdict: lever arm |")
    print("|---|---|---|---|---|---|---|---|")
    for scenario in SCENARIOS:
        for grade in GRADES:
            for seed in SEEDS:
                d = W / f"{scenario}-{grade}-{seed}"
                sim = d / "sim"
                if not (sim / "rig.csv").exists():
                    if run([B, "simulate", "--quiet", "--internal-rate", "0", "--scenario", scenario,
                            "--duration", DURATION, "--imu-grade", grade, "--seed", seed,
                            "--set", f"gnss.lever_arm_m={LEVER}", "--output", str(sim)]) != 0:
                        sys.exit(f"simulate failed: {sim}")
                right = None
                for name, lever, est in SHEETS:
                    tag = name.replace(" + ", "-")
                    sp = d / f"{tag}.yaml"
                    sheet(sp, grade, lever, est)
                    out = d / tag
                    rc = run([B, "process", str(sim / "rig.csv"), "--sensor", str(sp),
                              "--output", str(out), "--force"], d / f"{tag}.log")
                    if rc != 0:
                        print(f"| {scenario} | {grade} | {seed} | {name} | process failed ({rc}) | | | |")
                        continue
                    js = out / "eval.json"
                    run([B, "eval", "--truth", str(sim / "truth.nav"), "--nav",
                         str(out / "fuse" / "navresult.nav"), "--json", str(js)])
                    h = json.loads(js.read_text())["pos_horizontal_m"]["rms"]
                    right = h if right is None else right
                    s = json.loads((out / "fuse" / "summary.json").read_text())
                    la = s.get("lever_arm")
                    lv = "–"
                    if la:
                        lv = ", ".join(f"{e:+.3f} ± {sd:.3f}" for e, sd in zip(la["estimate_m"], la["sd_m"]))
                    v = verdict_of(out / "report.html")
                    lc = [c for c in v["checks"] if c["name"].startswith("antenna lever arm")
                          or c["name"].startswith("innovations vs heading")]
                    vt = v["grade"] + ": " + ", ".join(f"{c['name']} {c.get('grade')}" for c in lc)
                    print(f"| {scenario} | {grade} | {seed} | {name} | {h:.3f} | {h / right:.2f} | {lv} | {vt} |",
                          flush=True)


main()
