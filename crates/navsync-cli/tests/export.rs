//! `navsync export` end to end: GPX 1.1 and KML 2.2 validated against
//! their schemas with `xmllint` (vendored XSDs in tests/schemas; skipped
//! with a note when xmllint is missing: `.ci/run` installs it under CI),
//! CSV and GeoJSON read back and compared with the nav file to the printed
//! precision, σ from a std.txt beside the nav file, bad input reported.

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{bin, run, temp_dir};
use navsync::Diagnostics;
use navsync::io::export::decimate;
use navsync::io::kfgins::{NavReader, NavRecord};

/// The first 20 s (4000 epochs at 200 Hz) of the shared simulated drive's
/// truth as `navresult.nav`, and a 1 Hz `std.txt` beside it whose σ grow
/// linearly (so interpolated values are checkable).
fn write_set(dir: &Path) -> PathBuf {
    let truth = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/sim-drive-adis16465/truth.nav");
    let text = std::fs::read_to_string(&truth).unwrap();
    let nav: String = text.lines().take(4000).map(|l| format!("{l}\n")).collect();
    let p = dir.join("navresult.nav");
    std::fs::write(&p, nav).unwrap();
    let mut std_txt = String::new();
    for k in 0..=20 {
        let s = 0.01 * (1 + k) as f64;
        writeln!(
            std_txt,
            "{:.9} {s:.6} {:.6} {:.6} 0.001 0.002 0.003 0.01 0.02 0.3 0 0 0 0 0 0 0 0 0 0 0 0",
            100000.0 + k as f64,
            2.0 * s,
            3.0 * s
        )
        .unwrap();
    }
    std::fs::write(dir.join("std.txt"), std_txt).unwrap();
    p
}

fn nav_records(p: &Path, every_s: f64) -> Vec<NavRecord> {
    let mut d = Diagnostics::default();
    decimate(&NavReader::read_all(p, &mut d).unwrap(), every_s)
}

/// `xmllint --noout --schema` on `file`; `None` when xmllint is missing.
fn xmllint(schema: &str, file: &Path) -> Option<(bool, String)> {
    let xsd = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/schemas")
        .join(schema);
    match Command::new("xmllint")
        .args(["--noout", "--nonet", "--schema"])
        .arg(&xsd)
        .arg(file)
        .output()
    {
        Ok(o) => Some((
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )),
        Err(_) => {
            println!(
                "note: xmllint not found: schema validation of {schema} skipped (CI=true .ci/run installs libxml2-utils)"
            );
            None
        }
    }
}

#[test]
fn gpx_validates_against_gpx_1_1_and_carries_msl_height_time_and_sd() {
    let dir = temp_dir("gpx");
    let nav = write_set(&dir);
    let (ok, out, err) = run(bin()
        .args(["export", "--to", "gpx", "--every", "1"])
        .arg(&nav));
    assert!(ok, "{out}{err}");
    assert!(out.contains("21 epochs (21 with σ"), "{out}");
    let gpx_path = dir.join("navresult.gpx");
    let gpx = std::fs::read_to_string(&gpx_path).unwrap();
    assert_eq!(gpx.matches("<trkpt ").count(), 21);
    assert_eq!(gpx.matches("<navsync:sd_n_m>").count(), 21);
    // Week 2300 sow 100000.005 = 2024-02-05 03:46:22.005 UTC (GPS − UTC = 18 s).
    assert!(
        gpx.contains("<time>2024-02-05T03:46:22.005Z</time>"),
        "{}",
        &gpx[..800]
    );
    // ele = h − N: the drive starts at h = 20.9 m; EGM96 N near Wuhan is
    // about −13 m, so ele is ~34 m.
    let recs = nav_records(&nav, 1.0);
    let first = gpx.split("<trkpt ").nth(1).unwrap();
    let num = |tag: &str| -> f64 {
        let s = first.split(&format!("<{tag}>")).nth(1).unwrap();
        s.split('<').next().unwrap().parse().unwrap()
    };
    let (ele, n) = (num("ele"), num("geoidheight"));
    assert!((ele + n - recs[0].h_m).abs() < 1e-3, "{ele} {n}");
    assert!((-20.0..-5.0).contains(&n), "EGM96 N at 30.4N 114.5E: {n}");
    // σ at whole seconds are the std.txt values (1 Hz): second k has 0.01(1+k).
    assert!(gpx.contains("<navsync:sd_n_m>0.0200</navsync:sd_n_m><navsync:sd_e_m>0.0400</navsync:sd_e_m><navsync:sd_d_m>0.0600</navsync:sd_d_m>"));
    if let Some((valid, msg)) = xmllint("gpx-1.1.xsd", &gpx_path) {
        assert!(valid, "GPX 1.1 schema: {msg}");
    }
}

#[test]
fn kml_validates_against_ogc_kml_2_2() {
    let dir = temp_dir("kml");
    let nav = write_set(&dir);
    let out_path = dir.join("track.kml");
    let (ok, out, err) = run(bin()
        .args(["export", "--to", "kml", "--every", "0.5", "--output"])
        .arg(&out_path)
        .arg(&nav));
    assert!(ok, "{out}{err}");
    let kml = std::fs::read_to_string(&out_path).unwrap();
    assert_eq!(kml.matches("<Point>").count(), 41);
    assert_eq!(kml.matches("<TimeStamp>").count(), 41);
    assert_eq!(kml.matches("<Data name=\"sd_d_m\">").count(), 41);
    if let Some((valid, msg)) = xmllint("ogckml22.xsd", &out_path) {
        assert!(valid, "KML 2.2 schema: {msg}");
    }
}

#[test]
fn csv_and_geojson_read_back_to_the_nav_file() {
    let dir = temp_dir("csv");
    let nav = write_set(&dir);
    let recs = nav_records(&nav, 0.25);
    assert_eq!(recs.len(), 81);

    let (ok, out, err) = run(bin()
        .args(["export", "--to", "csv", "--every", "0.25"])
        .arg(&nav));
    assert!(ok, "{out}{err}");
    let csv = std::fs::read_to_string(dir.join("navresult.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header[..11],
        [
            "week",
            "sow_s",
            "lat_deg",
            "lon_deg",
            "h_m",
            "vn_mps",
            "ve_mps",
            "vd_mps",
            "roll_deg",
            "pitch_deg",
            "yaw_deg"
        ]
    );
    assert_eq!(header[11..14], ["sd_n_m", "sd_e_m", "sd_d_m"]);
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), recs.len());
    for (r, n) in rows.iter().zip(&recs) {
        assert_eq!(r[0] as i64, n.week);
        assert!((r[1] - n.time.sow()).abs() < 1e-9);
        let want = [
            n.lat_deg,
            n.lon_deg,
            n.h_m,
            n.vel[0],
            n.vel[1],
            n.vel[2],
            n.att_deg[0],
            n.att_deg[1],
            n.att_deg[2],
        ];
        // The nav file prints 1e-12 deg, 1e-6 m, 1e-9 m/s and deg: CSV keeps them.
        for k in 0..9 {
            assert!(
                (r[2 + k] - want[k]).abs() < 1e-9,
                "column {k}: {} vs {}",
                r[2 + k],
                want[k]
            );
        }
        // σ interpolated between the 1 Hz lines: sd_n = 0.01 (1 + t − 100000).
        let sd_n = 0.01 * (1.0 + n.time.sow() - 100000.0);
        assert!((r[11] - sd_n).abs() < 1e-6, "{} {sd_n}", r[11]);
        assert!((r[13] - 3.0 * sd_n).abs() < 1e-6);
    }

    let (ok, out, err) = run(bin()
        .args(["export", "--to", "geojson", "--every", "0.25"])
        .arg(&nav));
    assert!(ok, "{out}{err}");
    let gj: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("navresult.geojson")).unwrap())
            .unwrap();
    let feats = gj["features"].as_array().unwrap();
    assert_eq!(feats.len(), recs.len() + 1);
    for (f, n) in feats[1..].iter().zip(&recs) {
        let c = f["geometry"]["coordinates"].as_array().unwrap();
        assert!((c[0].as_f64().unwrap() - n.lon_deg).abs() < 1e-11);
        assert!((c[1].as_f64().unwrap() - n.lat_deg).abs() < 1e-11);
        assert!((c[2].as_f64().unwrap() - n.h_m).abs() < 1e-6);
        assert!((f["properties"]["yaw_deg"].as_f64().unwrap() - n.att_deg[2]).abs() < 1e-9);
        assert!((f["properties"]["sow_s"].as_f64().unwrap() - n.time.sow()).abs() < 1e-9);
    }
}

#[test]
fn tum_and_bad_input() {
    let dir = temp_dir("tum");
    let nav = write_set(&dir);
    let (ok, out, err) = run(bin().args(["export", "--to", "tum", "--no-std"]).arg(&nav));
    assert!(ok, "{out}{err}");
    assert!(out.contains("4000 epochs (0 with σ"), "{out}");
    let tum = std::fs::read_to_string(dir.join("navresult.tum")).unwrap();
    let rows: Vec<&str> = tum.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(rows.len(), 4000);
    assert!(rows.iter().all(|r| r.split(' ').count() == 8));

    // Bad lines are reported with file:line and skipped; bad options refused.
    let bad = dir.join("bad.nav");
    std::fs::write(
        &bad,
        "2300 100.0 30 114 20 0 0 0 0 0 45\n2300 101.0 30 x 20 0 0 0 0 0 45\n2300 102.0 30 114\n2300 103.0 30.00001 114 20 0 0 0 0 0 45\n",
    )
    .unwrap();
    let (ok, out, err) = run(bin().args(["export", "--to", "csv"]).arg(&bad));
    assert!(ok, "{out}{err}");
    assert!(out.contains("2 epochs"), "{out}");
    assert!(
        err.contains("bad.nav:2:") && err.contains("bad.nav:3:"),
        "{err}"
    );
    let (ok, _, err) = run(bin()
        .args(["export", "--to", "csv", "--every", "-1"])
        .arg(&bad));
    assert!(!ok && err.contains("--every"), "{err}");
    let empty = dir.join("empty.nav");
    std::fs::write(&empty, "# nothing\n").unwrap();
    let (ok, _, err) = run(bin().args(["export", "--to", "gpx"]).arg(&empty));
    assert!(
        !ok && err.contains("no navigation records") && !err.contains("panicked"),
        "{err}"
    );
}
