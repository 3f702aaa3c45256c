//! End-to-end tests of `navsync demo` and `navsync report`: the report's
//! metrics are `navsync eval`'s on the same files, the page is
//! self-contained, and bad inputs give errors naming file and line.

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use common::{bin, json, run, temp_dir};
use serde_json::Value;

/// The metrics JSON a report page carries.
fn embedded_eval(html: &Path) -> Value {
    let text = std::fs::read_to_string(html).unwrap();
    let tag = "<script type=\"application/json\" id=\"navsync-eval\">";
    let start = text.find(tag).expect("metrics block") + tag.len();
    let end = start + text[start..].find("</script>").unwrap();
    serde_json::from_str(&text[start..end]).unwrap()
}

#[test]
fn the_demo_report_shows_what_eval_computes() {
    let dir = temp_dir("demo");
    let demo = dir.join("demo");
    // 300 s: the PPS dropout (150 s) and the first GNSS outage (240 s).
    let (ok, out, err) = run(bin()
        .args(["demo", "--duration", "300", "--output"])
        .arg(&demo));
    assert!(ok, "{out}\n{err}");
    assert!(
        out.contains("position RMS") && out.contains("time offset"),
        "{out}"
    );
    for f in [
        "report.html",
        "eval.json",
        "demo.json",
        "sim/truth.nav",
        "sim/rig.csv",
        "synced/sync_report.json",
        "synced/imu.txt",
        "fused/navresult.nav",
        "fused/std.txt",
        "fused/imu_err.txt",
        "fused/time_offset.txt",
        "fused/summary.json",
        "fused/gnss_residuals.txt",
    ] {
        assert!(demo.join(f).is_file(), "{f} missing");
    }
    let outages = "100240:30,100420:30";
    let eval_json = dir.join("eval.json");
    let (ok, _, err) = run(bin()
        .args(["eval", "--truth"])
        .arg(demo.join("sim/truth.nav"))
        .arg("--nav")
        .arg(demo.join("fused/navresult.nav"))
        .args(["--outages", outages, "--json"])
        .arg(&eval_json));
    assert!(ok, "{err}");
    let want = json(&eval_json);
    assert_eq!(want["outages"].as_array().unwrap().len(), 1);
    // The demo's page and its eval.json hold exactly eval's figures.
    assert_eq!(embedded_eval(&demo.join("report.html")), want);
    assert_eq!(json(&demo.join("eval.json")), want);

    // `navsync report` on the files rebuilds the same figures.
    let page = dir.join("r.html");
    let (ok, out, err) = run(bin()
        .args(["report", "--truth"])
        .arg(demo.join("sim/truth.nav"))
        .arg("--nav")
        .arg(demo.join("fused/navresult.nav"))
        .arg("--sync-report")
        .arg(demo.join("synced/sync_report.json"))
        .arg("--imu-err-truth")
        .arg(demo.join("sim/imu_err_truth.txt"))
        .arg("--gnss")
        .arg(demo.join("synced/gnss.txt"))
        .args([
            "--outages",
            outages,
            "--time-offset-truth",
            "0.01",
            "--output",
        ])
        .arg(&page));
    assert!(ok, "{out}\n{err}");
    assert_eq!(embedded_eval(&page), want);
    let html = std::fs::read_to_string(&page).unwrap();
    // The table shows the same numbers as `navsync eval` prints.
    for key in ["pos_horizontal_m", "vel_3d_mps", "yaw_deg"] {
        let rms = want[key]["rms"].as_f64().unwrap();
        assert!(html.contains(&format!("<td>{rms:.4}</td>")), "{key} {rms}");
    }
    let drift = want["outage_rms_max_horizontal_m"].as_f64().unwrap();
    assert!(html.contains(&format!("<b>{drift:.3} m</b>")));
    // Every figure (trajectory, position, velocity, attitude, IMU errors
    // and GNSS weighting found beside the nav file, time offset, timeline,
    // latency; and the verdict's: bias envelope, innovations, NIS, σ)
    // inline, nothing fetched.
    assert_eq!(html.matches("<svg").count(), 13, "figures");
    for section in [
        "verdict",
        "trajectory",
        "imu",
        "imu-envelope",
        "gnss-weighting",
        "innovations",
        "nis",
        "filter-sigma",
        "time-offset",
        "sync",
        "latency",
    ] {
        assert!(
            html.contains(&format!("<section id=\"{section}\">")),
            "{section}"
        );
    }
    assert!(!html.contains("src=") && !html.contains("https:"));
    assert_eq!(
        html.matches("http:").count(),
        html.matches("xmlns=\"http://www.w3.org/2000/svg\"").count()
    );
    assert!(html.len() < 2_000_000, "{} bytes", html.len());
}

/// A few epochs of a standing vehicle: truth and a solution 1 m north.
fn write_nav_pair(dir: &Path) -> (PathBuf, PathBuf) {
    let (mut truth, mut nav) = (String::new(), String::new());
    for k in 0..50 {
        let t = 1000.0 + 0.1 * k as f64;
        writeln!(truth, "2300 {t:.3} 30.5 114.3 20.0 0 0 0 0 0 45").unwrap();
        writeln!(nav, "2300 {t:.3} 30.50000903 114.3 20.0 0 0 0 0 0 45").unwrap();
    }
    let (tp, np) = (dir.join("truth.nav"), dir.join("navresult.nav"));
    std::fs::write(&tp, truth).unwrap();
    std::fs::write(&np, nav).unwrap();
    (tp, np)
}

#[test]
fn report_bad_inputs_name_file_and_line() {
    let dir = temp_dir("bad");
    let (truth, nav) = write_nav_pair(&dir);
    // Inputs apart from the nav file (files beside it are picked up).
    let inp = dir.join("in");
    std::fs::create_dir_all(&inp).unwrap();
    let page = dir.join("r.html");
    let report = |extra: &[&str], files: &[(&str, &Path)]| {
        let mut c = bin();
        c.args(["report", "--truth"])
            .arg(&truth)
            .arg("--nav")
            .arg(&nav)
            .arg("--output")
            .arg(&page)
            .args(extra);
        for (flag, p) in files {
            c.arg(flag).arg(p);
        }
        run(&mut c)
    };
    // Good inputs work: 1 m north error.
    let (ok, out, err) = report(&[], &[]);
    assert!(ok, "{out}\n{err}");
    let e = embedded_eval(&page);
    assert!(
        (e["pos_north_m"]["rms"].as_f64().unwrap() - 1.0).abs() < 0.01,
        "{e}"
    );

    // A missing file.
    let (ok, _, err) = report(&[], &[("--std", Path::new("/no/such/std.txt"))]);
    assert!(!ok && err.contains("/no/such/std.txt"), "{err}");

    // A malformed std.txt line.
    let row = |sow: f64| {
        let mut s = format!("{sow:.3}");
        for _ in 0..21 {
            s.push_str(" 0.1");
        }
        s
    };
    let std = inp.join("std.txt");
    std::fs::write(
        &std,
        format!("{}\n{}\n1000.2 0.1 oops\n", row(1000.0), row(1000.1)),
    )
    .unwrap();
    let (ok, _, err) = report(&[], &[("--std", &std)]);
    assert!(
        !ok && err.contains("std.txt:3") && err.contains("expected 22 columns"),
        "{err}"
    );
    let bad_number = inp.join("std2.txt");
    std::fs::write(&bad_number, row(1000.0).replacen(" 0.1", " x", 1) + "\n").unwrap();
    let (ok, _, err) = report(&[], &[("--std", &bad_number)]);
    assert!(!ok && err.contains("std2.txt:1: column 2"), "{err}");

    // An imu_err.txt given as --std (13 columns, not 22).
    let imu_err = inp.join("imu_err.txt");
    std::fs::write(&imu_err, "1000.0 1 2 3 4 5 6 7 8 9 10 11 12\n").unwrap();
    let (ok, _, err) = report(&[], &[("--std", &imu_err)]);
    assert!(
        !ok && err.contains("imu_err.txt:1") && err.contains("found 13"),
        "{err}"
    );

    // A sync report that is not one.
    let sync = inp.join("sync.json");
    std::fs::write(&sync, "{\n  \"mode\": \"hw\",\n  \"causal\": 3\n}\n").unwrap();
    let (ok, _, err) = report(&[], &[("--sync-report", &sync)]);
    assert!(!ok && err.contains("sync.json:3"), "{err}");

    // A bad outage list and a truth without overlap.
    let (ok, _, err) = report(&["--outages", "1000:x"], &[]);
    assert!(!ok && err.contains("1000:x"), "{err}");
    let far = inp.join("far.nav");
    std::fs::write(
        &far,
        std::fs::read_to_string(&truth)
            .unwrap()
            .replace(" 100", " 200"),
    )
    .unwrap();
    let (ok, _, err) = run(bin()
        .args(["report", "--truth"])
        .arg(&far)
        .arg("--nav")
        .arg(&nav)
        .arg("--output")
        .arg(&page));
    assert!(!ok && err.contains("no epoch overlaps"), "{err}");
    assert!(!err.contains("panicked"));
}

/// The verdict JSON a report page carries.
fn embedded_verdict(html: &str) -> Value {
    let tag = "<script type=\"application/json\" id=\"navsync-verdict\">";
    let start = html.find(tag).expect("verdict block") + tag.len();
    let end = start + html[start..].find("</script>").unwrap();
    serde_json::from_str(&html[start..end]).unwrap()
}

fn check<'a>(v: &'a Value, name: &str) -> &'a Value {
    v["checks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == name)
        .unwrap_or_else(|| panic!("no check {name}: {v}"))
}

#[test]
fn a_report_without_truth_judges_the_run_from_its_own_statistics() {
    // A 200 s drive (ADIS16465-class IMU, 1 Hz RTK-class fixes) fused with
    // two 20 s outages: what a user without a reference has.
    let dir = temp_dir("truthless");
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args(["simulate", "--quiet", "--internal-rate", "0"])
        .args(["--scenario", "test-track", "--duration", "200"])
        .args(["--imu-grade", "adis16465", "--seed", "3", "--output"])
        .arg(&sim));
    assert!(ok, "{err}");
    let out = dir.join("out");
    let (ok, text, err) = run(bin()
        .args(["fuse", "--outage-period", "100", "--outage-len", "20"])
        .args(["--outage-first", "60", "--config"])
        .arg(sim.join("kf-gins.yaml"))
        .arg("--output")
        .arg(&out));
    assert!(ok, "{text}\n{err}");
    // The configured IMU model is in summary.json, in the YAML's units.
    let summary = json(&out.join("summary.json"));
    let gbstd = summary["imu_model"]["gyro_bias_sd_deg_h"][0]
        .as_f64()
        .unwrap();
    assert!((gbstd - 2.0).abs() < 1e-9, "{}", summary["imu_model"]);

    let page = dir.join("r.html");
    let (ok, text, err) = run(bin()
        .arg("report")
        .arg("--nav")
        .arg(out.join("navresult.nav"))
        .arg("--gnss")
        .arg(sim.join("gnss.txt"))
        .arg("--output")
        .arg(&page));
    assert!(ok, "{text}\n{err}");
    assert!(text.contains("no truth, verdict: "), "{text}");
    let html = std::fs::read_to_string(&page).unwrap();
    for id in [
        "verdict",
        "trajectory",
        "innovations",
        "nis",
        "gnss-weighting",
        "filter-sigma",
        "imu",
        "imu-envelope",
        "gaps",
        "outage-drift",
    ] {
        assert!(html.contains(&format!("<section id=\"{id}\">")), "{id}");
    }
    // No truth: no error plots, no scores.
    assert!(!html.contains("<section id=\"position\">") && !html.contains("navsync-eval"));
    // The verdict heads the page and names its grade.
    let v = embedded_verdict(&html);
    let words = match v["grade"].as_str().unwrap() {
        "good" => "good",
        "caution" => "usable with caution",
        "poor" => "poor",
        g => panic!("grade {g}"),
    };
    assert!(text.contains(&format!("verdict: {words};")), "{text}");
    let top = html.find("<section id=\"verdict\">").unwrap();
    assert!(top < html.find("<section id=\"trajectory\">").unwrap());
    // 159 fixes fused (40 withheld), the NIS mean tested against χ²(3n)/n.
    let nis = check(&v, "NIS mean");
    assert!(
        nis["finding"].as_str().unwrap().contains("over 159 fixes"),
        "{nis}"
    );
    // Six bias axes against the configured envelope.
    let bias = check(&v, "IMU biases vs datasheet");
    assert!(bias["finding"].as_str().unwrap().contains("of 6"), "{bias}");
    // The two scheduled outages, each with the filter's σ growing through
    // it: an ADIS16465 coasting 20 s drifts far beyond an RTK fix's σ.
    let drift = &html[html.find("<section id=\"outage-drift\">").unwrap()..];
    let rows: Vec<&str> = drift
        .lines()
        .filter(|l| l.contains("scheduled outage"))
        .collect();
    assert_eq!(rows.len(), 2, "{drift}");
    for r in rows {
        let cells: Vec<f64> = r
            .split("<td>")
            .filter_map(|c| {
                c.split("</td>")
                    .next()?
                    .trim_start_matches('×')
                    .parse()
                    .ok()
            })
            .collect();
        // start, length, σ start, σ end, growth, 3σ end
        assert_eq!(cells.len(), 6, "{r}");
        assert!((cells[1] - 20.0).abs() < 0.1, "{r}");
        assert!(cells[3] > 5.0 * cells[2] && cells[3] > 0.1, "{r}");
    }
    // Self-contained as before.
    assert!(!html.contains("src=") && !html.contains("https:"));

    // With --truth: today's error sections and scores, plus the verdict.
    let (ok, text, err) = run(bin()
        .args(["report", "--truth"])
        .arg(sim.join("truth.nav"))
        .arg("--nav")
        .arg(out.join("navresult.nav"))
        .arg("--output")
        .arg(&page));
    assert!(ok, "{text}\n{err}");
    let html = std::fs::read_to_string(&page).unwrap();
    for id in [
        "verdict",
        "position",
        "velocity",
        "attitude",
        "nis",
        "outage-drift",
    ] {
        assert!(html.contains(&format!("<section id=\"{id}\">")), "{id}");
    }
    assert!(embedded_eval(&page)["epochs_compared"].as_u64().unwrap() > 1000);

    // A nav file that is missing: the error names it.
    let missing = dir.join("nowhere/navresult.nav");
    let (ok, _, err) = run(bin()
        .arg("report")
        .arg("--nav")
        .arg(&missing)
        .arg("--output")
        .arg(&page));
    assert!(!ok && err.contains("nowhere/navresult.nav"), "{err}");
    assert!(!err.contains("panicked"));
    // A gnss_residuals.txt beside the nav file that is not one: file and line.
    let bad = dir.join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    std::fs::copy(out.join("navresult.nav"), bad.join("navresult.nav")).unwrap();
    std::fs::write(
        bad.join("gnss_residuals.txt"),
        "# header\n100001.000 position 0 0 0 1 1 1 0.5 1 1 1 used\n100002.000 position 0 0\n",
    )
    .unwrap();
    let (ok, _, err) = run(bin()
        .arg("report")
        .arg("--nav")
        .arg(bad.join("navresult.nav"))
        .arg("--output")
        .arg(&page));
    assert!(
        !ok && err.contains("gnss_residuals.txt:3") && err.contains("expected 15 columns"),
        "{err}"
    );
}
