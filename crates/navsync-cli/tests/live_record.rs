//! `navsync live --record` on pseudo-terminals (the self-test's replay, at
//! real rate): a run killed with SIGKILL leaves a rig log that `sync`
//! reads, holding what was sent until 1 s before the kill; a whole run's
//! recording, synced and fused offline, matches the live solution.
#![cfg(target_os = "linux")]

mod common;

use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

use common::{bin, run, temp_dir};
use navsync::time::{GpsTime, NS_PER_S};
use navsync_live::hostclock;
use navsync_live::replay::{ReplayClock, ReplayConfig, imu_truth};

/// The number after `word` in `text` ("received 3000" → 3000).
fn number_after(text: &str, word: &str) -> u64 {
    let at = text
        .find(word)
        .unwrap_or_else(|| panic!("'{word}' not in:\n{text}"));
    text[at + word.len()..]
        .trim_start()
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after '{word}' in:\n{text}"))
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("sync_report.json")).unwrap()).unwrap()
}

/// Records of each kind the self-test's replay sent before host counter
/// `until_ns` (its schedule: IMU line k at its true time, GNSS epoch m
/// 40 ms after m/10 s, a pulse at every second).
fn sent_before(cfg: &ReplayConfig, clock: &ReplayClock, until_ns: u64) -> [u64; 3] {
    let before = |t: GpsTime| clock.host_at(t) < until_ns;
    let imu = (0..).take_while(|&k| before(imu_truth(cfg, k))).count() as u64;
    let gnss = (1..)
        .take_while(|&m| {
            before(
                cfg.start
                    .add_seconds(m as f64 / cfg.gnss_rate_hz + cfg.gnss_latency_s),
            )
        })
        .count() as u64;
    let pps = (1..)
        .take_while(|&s| before(cfg.start + s * NS_PER_S))
        .count() as u64;
    [imu, gnss, pps]
}

/// Kill after NAVSYNC_RECORD_KILL_S seconds (8 by default; 20 for the
/// documented figure).
#[test]
fn a_recording_killed_with_sigkill_holds_what_was_sent_until_a_second_before() {
    let kill_s: f64 = std::env::var("NAVSYNC_RECORD_KILL_S")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(8.0);
    let dir = temp_dir("kill");
    let (rig, raw, log) = (
        dir.join("rig.csv"),
        dir.join("raw.ubx"),
        dir.join("out.txt"),
    );
    let mut child = bin()
        .args(["live", "--selftest", "--minutes", "5", "--pps-gap", "0"])
        .arg("--record")
        .arg(&rig)
        .arg("--record-gnss")
        .arg(&raw)
        .stdout(Stdio::from(std::fs::File::create(&log).unwrap()))
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The child tells where its replay's clock starts.
    let mut host0 = None;
    for _ in 0..200 {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        if text.contains(" ns (CLOCK_MONOTONIC_RAW)") {
            host0 = Some(number_after(&text, "at host counter"));
            break;
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    let Some(host0) = host0 else {
        let _ = child.kill();
        panic!(
            "no replay clock line: {}",
            std::fs::read_to_string(&log).unwrap()
        );
    };
    let cfg = ReplayConfig::default();
    let clock = ReplayClock {
        host0,
        gps0: cfg.start,
        host_ppm: cfg.host_ppm,
    };
    let kill_at = host0 + (kill_s * 1e9) as u64;
    while hostclock::now_ns() < kill_at {
        std::thread::sleep(Duration::from_millis(5));
    }
    let killed_ns = hostclock::now_ns();
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    // A killed selftest cannot remove its PTY links (live.rs names the
    // directory after its process).
    let _ = std::fs::remove_dir_all(
        std::env::temp_dir().join(format!("navsync-live-selftest-{}", child.id())),
    );
    let sent = sent_before(&cfg, &clock, killed_ns - NS_PER_S as u64);

    let out = dir.join("sync");
    let (ok, so, se) = run(bin().arg("sync").arg(&rig).arg("--output").arg(&out));
    assert!(ok, "{so}\n{se}");
    let r = report(&out);
    assert_eq!(r["mode"], "hybrid", "{so}");
    let rec = &r["records"];
    let kept = [
        rec["imu"].as_u64().unwrap(),
        rec["gnss"].as_u64().unwrap(),
        rec["pps"].as_u64().unwrap(),
    ];
    let (k, s) = (kept.iter().sum::<u64>(), sent.iter().sum::<u64>());
    let sent_all = sent_before(&cfg, &clock, killed_ns);
    eprintln!(
        "killed after {:.2} s: kept imu/gnss/pps {kept:?}; sent until 1 s before the kill {sent:?} ({:.1} % kept), until the kill {sent_all:?} (the last {:.2} s of IMU lines lost)",
        (killed_ns - host0) as f64 * 1e-9,
        100.0 * k as f64 / s as f64,
        sent_all[0].saturating_sub(kept[0]) as f64 / cfg.imu_rate_hz
    );
    assert!(sent[0] as f64 >= 150.0 * (kill_s - 2.0), "{sent:?}");
    assert!(k as f64 >= 0.99 * s as f64, "kept {kept:?} of {sent:?}");
    for (k, s) in kept.iter().zip(&sent) {
        assert!(*k as f64 >= 0.99 * *s as f64, "kept {kept:?} of {sent:?}");
    }
    // A torn last line is skipped by name and line; the rest is kept.
    let text = std::fs::read(&rig).unwrap();
    assert_eq!(text.last(), Some(&b'\n'));
    let lines = text.iter().filter(|&&b| b == b'\n').count();
    let cut = dir.join("cut.csv");
    std::fs::write(&cut, &text[..text.len() - 20]).unwrap();
    let out_cut = dir.join("sync-cut");
    let (ok, so, se) = run(bin().arg("sync").arg(&cut).arg("--output").arg(&out_cut));
    assert!(ok, "{so}\n{se}");
    assert!(
        se.contains(&format!("cut.csv:{lines}:")) && se.contains("no end of line"),
        "{se}"
    );
    let rc = &report(&out_cut)["records"];
    let kept_cut =
        rc["imu"].as_u64().unwrap() + rc["gnss"].as_u64().unwrap() + rc["pps"].as_u64().unwrap();
    assert_eq!(kept_cut + 1, k);
    // The receiver's bytes convert again: whole UBX frames, every fix kept
    // in the rig log among them.
    let conv = dir.join("conv");
    let (ok, so, se) = run(bin()
        .args(["convert", "--from", "ubx"])
        .arg(&raw)
        .arg("--output")
        .arg(&conv));
    assert!(ok, "{so}\n{se}");
    let fixes = std::fs::read_to_string(conv.join("gnss.txt"))
        .unwrap()
        .lines()
        .count() as u64;
    assert!(
        fixes >= kept[1],
        "{fixes} fixes from raw.ubx, {kept:?} in the rig log"
    );
}

fn rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
        .collect()
}

#[test]
fn a_recording_synced_and_fused_offline_matches_the_live_solution() {
    let dir = temp_dir("match");
    let (rig, raw, live) = (dir.join("rig.csv"), dir.join("raw.ubx"), dir.join("live"));
    let (ok, so, se) = run(bin()
        .args(["live", "--selftest", "--minutes", "0.25", "--pps-gap", "0"])
        .arg("--record")
        .arg(&rig)
        .arg("--record-gnss")
        .arg(&raw)
        .arg("--output")
        .arg(&live));
    assert!(ok, "{so}\n{se}");
    let received = number_after(&so, "received");
    let fixes = number_after(&so, "epochs written,");
    let pulses = number_after(&so, "PPS:");
    assert!(
        so.contains(&format!(
            "recorded {received} imu, {fixes} gnss, {pulses} pps"
        )),
        "{so}"
    );

    // sync: every record back, hybrid mode from the header, plausible.
    let off = dir.join("off");
    let (ok, so2, se2) = run(bin().arg("sync").arg(&rig).arg("--output").arg(&off));
    assert!(ok, "{so2}\n{se2}");
    let r = report(&off);
    assert_eq!(r["mode"], "hybrid");
    assert_eq!(r["records"]["imu"], received);
    assert_eq!(r["records"]["gnss"], fixes);
    assert_eq!(r["records"]["pps"], pulses);
    assert_eq!(r["imu"]["lost"], 0);
    // The raw bytes give the same fixes, with the velocity live used.
    let conv = dir.join("conv");
    let (ok, so3, se3) = run(bin()
        .args(["convert", "--from", "ubx"])
        .arg(&raw)
        .arg("--output")
        .arg(&conv));
    assert!(ok, "{so3}\n{se3}");
    let (g_rig, g_raw) = (rows(&off.join("gnss.txt")), rows(&conv.join("gnss.txt")));
    assert_eq!(g_rig.len() as u64, fixes);
    assert_eq!(g_raw.len(), g_rig.len());
    for (a, b) in g_rig.iter().zip(&g_raw) {
        assert!(
            (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-10,
            "{a:?} {b:?}"
        );
        assert!((a[3] - b[3]).abs() < 1e-4 && b.len() == 13, "{a:?} {b:?}");
    }

    // fuse from the state live started from: its first fix, level, north.
    let started = so
        .lines()
        .find_map(|l| l.split("fusion started at ").nth(1))
        .unwrap_or_else(|| panic!("{so}"));
    let sow: f64 = started.split_whitespace().nth(1).unwrap().parse().unwrap();
    let f = g_raw
        .iter()
        .find(|g| (g[0] - sow).abs() < 1e-6)
        .unwrap_or_else(|| panic!("fix {sow} not in raw.ubx"));
    let cfg = format!(
        "imupath: \"{d}/off/imu.txt\"\ngnsspath: \"{d}/conv/gnss.txt\"\noutputpath: \"{d}/fused\"\n\
         imudatalen: 7\nimudatarate: 200\nstarttime: {sow:.9}\nendtime: -1\n\
         initpos: [ {:.11}, {:.11}, {:.4} ]\ninitvel: [ {}, {}, {} ]\ninitatt: [ 0, 0, 0 ]\n\
         initgyrbias: [ 0, 0, 0 ]\ninitaccbias: [ 0, 0, 0 ]\ninitgyrscale: [ 0, 0, 0 ]\ninitaccscale: [ 0, 0, 0 ]\n\
         initposstd: [ 1, 1, 1.5 ]\ninitvelstd: [ 0.1, 0.1, 0.1 ]\ninitattstd: [ 0.5, 0.5, 1.0 ]\n\
         imunoise:\n  arw: [ 0.15, 0.15, 0.15 ]\n  vrw: [ 0.04, 0.04, 0.04 ]\n  gbstd: [ 2, 2, 2 ]\n  \
         abstd: [ 3.6, 3.6, 3.6 ]\n  gsstd: [ 500, 500, 500 ]\n  asstd: [ 500, 500, 500 ]\n  corrtime: 1.0\n\
         antlever: [ 0, 0, 0 ]\n",
        f[1],
        f[2],
        f[3],
        f[4],
        f[5],
        f[6],
        d = dir.display()
    );
    let yaml = dir.join("kf-gins.yaml");
    std::fs::write(&yaml, cfg).unwrap();
    let (ok, so4, se4) = run(bin()
        .args(["fuse", "--week", "2400", "--config"])
        .arg(&yaml));
    assert!(ok, "{so4}\n{se4}");

    // Same epochs (the IMU stamps of sync and of live agree to well under
    // a sample period), same positions and attitude once both filters
    // have run 5 s.
    let (a, b) = (
        rows(&live.join("navresult.nav")),
        rows(&dir.join("fused/navresult.nav")),
    );
    let t_live0 = a[0][1];
    let (mut matched, mut dt_max, mut pos_max, mut att_max) = (0, 0.0f64, 0.0f64, 0.0f64);
    let mut pos_max_all = 0.0f64;
    let mut j = 0;
    for x in &a {
        while j + 1 < b.len() && (b[j + 1][1] - x[1]).abs() < (b[j][1] - x[1]).abs() {
            j += 1;
        }
        let y = &b[j];
        let dt = (y[1] - x[1]).abs();
        assert!(
            dt < 1e-3,
            "live epoch {} has no offline one (nearest {})",
            x[1],
            y[1]
        );
        matched += 1;
        dt_max = dt_max.max(dt);
        let lat = x[2].to_radians();
        let dn = (x[2] - y[2]).to_radians() * 6_378_137.0;
        let de = (x[3] - y[3]).to_radians() * 6_378_137.0 * lat.cos();
        let dd = x[4] - y[4];
        let d = (dn * dn + de * de + dd * dd).sqrt();
        pos_max_all = pos_max_all.max(d);
        if x[1] < t_live0 + 5.0 {
            continue;
        }
        pos_max = pos_max.max(d);
        for k in 8..11 {
            att_max = att_max.max((x[k] - y[k]).abs());
        }
    }
    eprintln!(
        "live vs offline: {matched} epochs matched, stamps within {:.1} µs; positions within {:.3} m, after 5 s within {:.3} m, attitude within {:.4}°",
        dt_max * 1e6,
        pos_max_all,
        pos_max,
        att_max
    );
    assert_eq!(matched, a.len());
    assert!(dt_max < 200e-6, "stamps differ by {dt_max} s");
    assert!(pos_max < 0.15, "positions differ by {pos_max} m");
    assert!(att_max < 0.05, "attitude differs by {att_max}°");
}
