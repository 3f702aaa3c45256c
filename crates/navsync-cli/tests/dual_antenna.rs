//! Dual-antenna heading end to end: a simulated drive (ADIS16465) whose
//! truth gives the antenna baseline's azimuth, with 0.2° receiver noise and
//! a 30° mounting yaw, fused without any initial attitude.

mod common;

use std::path::{Path, PathBuf};

use common::{bin, json, number_rows, run, simulate_adis16465, temp_dir};

const NOISE_SD_DEG: f64 = 0.2;
const MOUNT_YAW_DEG: f64 = 30.0;

fn simulate(dir: &Path, scenario: &str, duration_s: &str) -> PathBuf {
    simulate_with(dir, scenario, duration_s, &[])
}

/// [`simulate`] with more `simulate` options.
fn simulate_with(dir: &Path, scenario: &str, duration_s: &str, extra: &[&str]) -> PathBuf {
    let sim = simulate_adis16465(dir, scenario, duration_s, extra);
    // The configuration without an initial state: the run aligns itself.
    let cfg = std::fs::read_to_string(sim.join("kf-gins.yaml")).unwrap();
    let kept: String = cfg
        .lines()
        .filter(|l| {
            !(l.starts_with("initpos:") || l.starts_with("initvel:") || l.starts_with("initatt:"))
        })
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(sim.join("kf-gins-align.yaml"), kept).unwrap();
    sim
}

/// Rows of an 11-column nav file: (sow, roll, pitch, yaw) in degrees.
fn attitudes(path: &Path) -> Vec<(f64, f64, f64, f64)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter_map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect();
            (v.len() >= 11).then(|| (v[1], v[8], v[9], v[10]))
        })
        .collect()
}

/// Gaussian draws from a fixed-seed generator (splitmix64, Box–Muller).
struct Normal(u64);
impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn draw(&mut self) -> f64 {
        let (u1, u2) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// The heading file a moving-base receiver would give at 5 Hz: the
/// azimuth of C_b^n (cos α, sin α, 0) from the truth's attitude, plus
/// noise; each `bad` (seconds into the data, fields after the time) is a
/// line 0.1 s after the heading at that second.
fn heading_file(truth: &Path, out: &Path, bad: &[(f64, &str)]) {
    let mut rng = Normal(42);
    let a = MOUNT_YAW_DEG.to_radians();
    let mut text = String::from("# sow heading_deg sd_deg source\n");
    let rows = attitudes(truth);
    let t0 = rows[0].0.floor();
    for (sow, r, p, y) in rows {
        if ((sow * 5.0).round() - sow * 5.0).abs() > 1e-6 {
            continue;
        }
        let (r, p, y) = (r.to_radians(), p.to_radians(), y.to_radians());
        // az = ψ + atan2(w_y, w_x), w = R_y(θ) R_x(φ) (cos α, sin α, 0).
        let wx = p.cos() * a.cos() + p.sin() * a.sin() * r.sin();
        let wy = a.sin() * r.cos();
        let az = (y + wy.atan2(wx)).to_degrees() + NOISE_SD_DEG * rng.draw();
        text.push_str(&format!(
            "{sow:.3} {:.5} {NOISE_SD_DEG} baseline\n",
            az.rem_euclid(360.0)
        ));
        if let Some((_, l)) = bad.iter().find(|(k, _)| (t0 + k - sow).abs() < 1e-6) {
            text.push_str(&format!("{:.3} {l}\n", sow + 0.1));
        }
    }
    std::fs::write(out, text).unwrap();
}

fn fuse(sim: &Path, heading: &Path, out: &Path) -> (String, String) {
    let (ok, stdout, err) = run(bin()
        .arg("fuse")
        .arg("--config")
        .arg(sim.join("kf-gins-align.yaml"))
        .arg("--heading")
        .arg(heading)
        .args(["--dual-antenna-yaw", &MOUNT_YAW_DEG.to_string(), "--output"])
        .arg(out));
    assert!(ok, "{stdout}{err}");
    (stdout, err)
}

fn wrap180(d: f64) -> f64 {
    (d + 180.0).rem_euclid(360.0) - 180.0
}

/// The test track starts with a standstill: the run aligns one second in
/// from the baseline, its first epoch's heading within 1° of the truth
/// (the heading σ is √(0.2² + 0.5²)° with the mounting allowance); bad
/// heading lines are reported with file and line, and the run goes on.
#[test]
fn standstill_start_is_aligned_by_the_baseline_within_a_second() {
    let d = temp_dir("dual-start");
    let sim = simulate(&d, "test-track", "120");
    let h = d.join("heading.txt");
    heading_file(
        &sim.join("truth.nav"),
        &h,
        &[
            (10.0, "NaN 0.2 baseline"),
            (15.0, "80.0 180 baseline"),
            (20.0, "80.0"),
        ],
    );
    let out = d.join("out");
    let (stdout, _) = fuse(&sim, &h, &out);
    let s = json(&out.join("summary.json"));
    assert_eq!(
        s["alignment"]["method"], "static-levelling-and-dual-antenna",
        "{s}"
    );
    let truth = attitudes(&sim.join("truth.nav"));
    let nav = attitudes(&out.join("navresult.nav"));
    let (t0, first) = (truth[0].0, nav[0]);
    assert!(
        first.0 - t0 <= 2.0 + 1e-6,
        "the run starts at {} (data at {t0})",
        first.0
    );
    let at = |t: f64| {
        truth
            .iter()
            .find(|r| (r.0 - t).abs() < 1e-6)
            .copied()
            .unwrap()
    };
    let err0 = wrap180(first.3 - at(first.0).3);
    assert!(err0.abs() < 1.0, "heading error {err0}° at the first epoch");
    // Heading updates through the drive, none of the good ones rejected.
    assert!(stdout.contains("dual-antenna heading updates"), "{stdout}");
    assert_eq!(
        s["stats"]["heading_rejected"],
        serde_json::Value::Null,
        "{}",
        s["stats"]
    );
    assert!(
        s["stats"]["heading_updates"].as_u64().unwrap() > 500,
        "{}",
        s["stats"]
    );
    // The bad lines, by the line number the diagnostic gives.
    let diags = s["diagnostics"]["items"].as_array().unwrap();
    let bad: Vec<(u64, String)> = diags
        .iter()
        .filter(|x| x["file"].as_str().unwrap().ends_with("heading.txt"))
        .map(|x| {
            (
                x["line"].as_u64().unwrap(),
                x["message"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    assert_eq!(bad.len(), 3, "{bad:?}");
    let text = std::fs::read_to_string(&h).unwrap();
    for ((line, msg), want) in bad.iter().zip(["NaN", "180", "found 2"]) {
        let l = text.lines().nth(*line as usize - 1).unwrap();
        let fields = l.split_whitespace().count();
        assert!(
            l.contains("NaN") || l.contains(" 180 ") || fields == 2,
            "line {line} is `{l}`, a good line: {msg}"
        );
        assert!(msg.contains(want), "{msg}");
    }
}

/// A vehicle that never moves gets its heading from the baseline: at every
/// epoch within the heading σ the filter states (std.txt), which keeps the
/// mounting allowance (the consider state: averaging cannot remove it).
#[test]
fn never_moving_drive_gets_its_heading_within_its_sigma() {
    let d = temp_dir("dual-static");
    let sim = simulate(&d, "static", "60");
    let h = d.join("heading.txt");
    heading_file(&sim.join("truth.nav"), &h, &[]);
    let out = d.join("out");
    fuse(&sim, &h, &out);
    let s = json(&out.join("summary.json"));
    assert_eq!(
        s["alignment"]["method"], "static-levelling-and-dual-antenna",
        "{s}"
    );
    let truth = attitudes(&sim.join("truth.nav"));
    let nav = attitudes(&out.join("navresult.nav"));
    let std = std::fs::read_to_string(out.join("std.txt")).unwrap();
    // std.txt: sow, position, velocity, attitude σ (deg), at its own rate.
    let yaw_sd: Vec<(f64, f64)> = std
        .lines()
        .filter_map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect();
            (v.len() > 9).then(|| (v[0], v[9]))
        })
        .collect();
    assert!(yaw_sd.len() > 500, "{} σ rows", yaw_sd.len());
    let mut worst: f64 = 0.0;
    for (t_sd, sd) in &yaw_sd {
        let n = nav.iter().find(|r| (r.0 - t_sd).abs() < 1e-6).unwrap();
        let t = truth.iter().find(|r| (r.0 - n.0).abs() < 1e-6).unwrap();
        let e = wrap180(n.3 - t.3);
        assert!(e.abs() <= *sd, "at {}: error {e}°, σ {sd}°", n.0);
        worst = worst.max(e.abs());
        // The mounting allowance stays in the σ.
        assert!(*sd >= 0.45 && *sd < 1.0, "σ {sd}°");
    }
    assert!(worst < 0.5, "worst heading error {worst}°");
}

/// A logger that writes the receiver's headings into its rig log
/// (`heading` records, as `live --record` does): `process` takes them
/// through `sync` (heading.txt) and aligns the vehicle that never moves
/// from the baseline, where without them its heading is unobservable.
#[test]
fn process_takes_heading_records_from_a_rig_log() {
    let d = temp_dir("dual-rig");
    let sim = simulate(&d, "static", "60");
    let h = d.join("heading.txt");
    heading_file(&sim.join("truth.nav"), &h, &[]);
    // One heading per fix: the one of the fix's epoch, received 1 µs after it.
    let headings: Vec<(f64, String)> = std::fs::read_to_string(&h)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f[0].parse().unwrap(), format!("{},{},{}", f[1], f[2], f[3]))
        })
        .collect();
    let mut rig = String::new();
    let mut added = 0;
    for line in std::fs::read_to_string(sim.join("rig.csv"))
        .unwrap()
        .lines()
    {
        rig.push_str(line);
        rig.push('\n');
        let f: Vec<&str> = line.split(',').collect();
        if f[0] != "gnss" {
            continue;
        }
        let (counter, week, tow): (u64, &str, f64) =
            (f[1].parse().unwrap(), f[2], f[3].parse().unwrap());
        if let Some((_, rest)) = headings.iter().find(|(t, _)| (t - tow).abs() < 1e-6) {
            rig.push_str(&format!("heading,{},{week},{},{rest}\n", counter + 1, f[3]));
            added += 1;
        }
    }
    assert!(added >= 50, "{added} headings");
    let rig_path = d.join("rig-with-headings.csv");
    std::fs::write(&rig_path, rig).unwrap();
    let sensor = d.join("sensor.yaml");
    let (ok, out, err) = run(bin()
        .args(["init", "--preset", "adis16465", "--output"])
        .arg(&sensor));
    assert!(ok, "{out}{err}");
    let text = std::fs::read_to_string(&sensor)
        .unwrap()
        .replace(
            "antenna_lever_m: [0.0, 0.0, 0.0]",
            "antenna_lever_m: [0.1, 0.5, -1.2]",
        )
        .replace(
            "dual_antenna_yaw_deg: 0.0",
            &format!("dual_antenna_yaw_deg: {MOUNT_YAW_DEG}"),
        );
    std::fs::write(&sensor, text).unwrap();
    let out = d.join("out");
    let (ok, stdout, err) = run(bin()
        .arg("process")
        .arg(&rig_path)
        .arg("--sensor")
        .arg(&sensor)
        .arg("--output")
        .arg(&out)
        .arg("--no-smooth"));
    assert!(ok, "{stdout}{err}");
    assert!(stdout.contains("heading.txt"), "{stdout}");
    let synced = std::fs::read_to_string(out.join("sync/heading.txt")).unwrap();
    assert_eq!(
        synced.lines().filter(|l| !l.starts_with('#')).count(),
        added
    );
    let p = json(&out.join("process.json"));
    assert_eq!(
        p["alignment"]["method"], "static-levelling-and-dual-antenna",
        "{p}"
    );
    let truth = attitudes(&sim.join("truth.nav"));
    let nav = attitudes(&out.join("fuse/navresult.nav"));
    let (n, t) = (nav.last().unwrap(), truth.last().unwrap());
    let e = wrap180(n.3 - t.3);
    assert!(e.abs() < 1.0, "final heading error {e}°");
}

/// `simulate --dual-antenna YAW,SD`: a heading with every fix, in
/// heading.txt and as rig-log records, from the truth's attitude; `sync`
/// gives back the same headings, bit for bit.
#[test]
fn simulated_dual_antenna_headings_follow_the_truth() {
    let d = temp_dir("dual-sim");
    let mount = format!("{MOUNT_YAW_DEG},{NOISE_SD_DEG}");
    let sim = simulate_with(&d, "static", "30", &["--dual-antenna", &mount]);
    let headings = number_rows(&sim.join("heading.txt"));
    let fixes = number_rows(&sim.join("gnss.txt"));
    assert_eq!(headings.len(), fixes.len());
    // The static vehicle faces its truth yaw: the baseline is 30° right of it.
    let truth = attitudes(&sim.join("truth.nav"));
    let yaw = truth[0].3;
    let errs: Vec<f64> = headings
        .iter()
        .map(|h| wrap180(h[1] - (yaw + MOUNT_YAW_DEG)))
        .collect();
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    assert!(
        (0.1..0.35).contains(&rms),
        "heading noise RMS {rms}° (σ 0.2°)"
    );
    let (ok, out, err) = run(bin()
        .arg("sync")
        .arg(sim.join("rig.csv"))
        .arg("--output")
        .arg(d.join("sync")));
    assert!(ok && out.contains("heading.txt"), "{out}{err}");
    assert_eq!(
        std::fs::read_to_string(d.join("sync/heading.txt")).unwrap(),
        std::fs::read_to_string(sim.join("heading.txt")).unwrap()
    );
}
