//! `navsync fuse --zupt`: standstill detection and zero-velocity /
//! zero-angular-rate updates, end to end on a simulated test-track drive
//! whose truth says when the vehicle stood.

mod common;

use std::path::Path;

use common::{bin, run, temp_dir};

/// Seconds the truth trajectory stands (horizontal speed < 1 cm/s) and the
/// number of stops.
fn true_standstill(truth: &Path) -> (f64, usize) {
    let text = std::fs::read_to_string(truth).unwrap();
    let mut total = 0.0;
    let mut stops = 0;
    let mut prev: Option<(f64, bool)> = None;
    for line in text.lines() {
        let v: Vec<f64> = line
            .split_whitespace()
            .filter_map(|x| x.parse().ok())
            .collect();
        let (t, still) = (v[1], v[5].hypot(v[6]) < 0.01);
        if let Some((tp, sp)) = prev {
            if still && sp {
                total += t - tp;
            }
            if still && !sp {
                stops += 1;
            }
        } else if still {
            stops += 1;
        }
        prev = Some((t, still));
    }
    (total, stops)
}

fn fuse(sim: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let (ok, text, err) = run(bin()
        .args(["fuse", "--outage-period", "1000", "--outage-len", "40"])
        .args(["--outage-first", "230", "--config"])
        .arg(sim.join("kf-gins.yaml"))
        .arg("--output")
        .arg(out)
        .args(extra));
    assert!(ok, "{text}\n{err}");
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

fn outage_drift(sim: &Path, out: &Path, outages: &str) -> f64 {
    let json = out.join("eval.json");
    let (ok, _, err) = run(bin()
        .args(["eval", "--truth"])
        .arg(sim.join("truth.nav"))
        .arg("--nav")
        .arg(out.join("navresult.nav"))
        .args(["--outages", outages, "--json"])
        .arg(&json));
    assert!(ok, "{err}");
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    e["outage_rms_max_horizontal_m"].as_f64().unwrap()
}

#[test]
fn stops_are_found_and_hold_the_solution_through_an_outage() {
    // A 300 s test-track drive (ADIS16465 class) that stands 40 s at the
    // start and stops three times; a 40 s GNSS outage from 230 s covers
    // the 7 s stop at 244–251 s. Through the stop the velocity error is
    // reset to the ZUPT's 2 cm/s instead of growing (δv ≈ g·δθ·t), so the
    // drift at the outage's end comes from the time after the stop only.
    let dir = temp_dir("zupt");
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args(["simulate", "--quiet", "--internal-rate", "0"])
        .args(["--scenario", "test-track", "--duration", "300"])
        .args(["--imu-grade", "adis16465", "--seed", "1", "--output"])
        .arg(&sim));
    assert!(ok, "{err}");
    let (still_s, stops) = true_standstill(&sim.join("truth.nav"));
    assert!(stops >= 3 && still_s > 50.0, "{stops} stops, {still_s} s");

    let plain = fuse(&sim, &dir.join("plain"), &[]);
    let zupt = fuse(&sim, &dir.join("zupt"), &["--zupt"]);
    assert_eq!(plain["stats"]["zupt_updates"].as_u64(), Some(0));
    // Found: at least 80 % of the standing time in 1 s windows, and no
    // more than the standing time plus one edge window per stop.
    let found = zupt["stats"]["standstill_s"].as_f64().unwrap();
    assert!(
        found >= 0.8 * still_s && found <= still_s + stops as f64 + 1.0,
        "detected {found} s still, truth {still_s} s in {stops} stops"
    );
    assert_eq!(
        zupt["stats"]["zupt_updates"].as_u64(),
        zupt["stats"]["zaru_updates"].as_u64()
    );
    let outages = zupt["outages"].as_str().unwrap().to_string();
    let d_plain = outage_drift(&sim, &dir.join("plain"), &outages);
    let d_zupt = outage_drift(&sim, &dir.join("zupt"), &outages);
    assert!(
        d_zupt < 0.8 * d_plain,
        "drift through the outage: {d_zupt} m with ZUPT, {d_plain} m without"
    );

    // A bad threshold is refused with the option's meaning.
    let (ok, _, err) = run(bin()
        .args(["fuse", "--zupt", "--zupt-accel-spread", "0", "--config"])
        .arg(sim.join("kf-gins.yaml"))
        .arg("--output")
        .arg(dir.join("bad")));
    assert!(
        !ok && err.contains("--zupt-accel-spread") && err.contains("out of range"),
        "{err}"
    );
}
