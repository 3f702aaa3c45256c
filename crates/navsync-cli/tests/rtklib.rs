//! `navsync fuse` with an RTKLIB `.pos` GNSS file: the shared simulated
//! drive's fixes written as RTKLIB llh (week tow) and xyz (calendar GPST)
//! solutions fuse to the same trajectory as the KF-GINS file; the Q filter
//! drops and counts what it should.

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use common::{bin, temp_dir};
use nalgebra::{Matrix3, Vector3};
use navsync::earth::{Geodetic, c_ne, geodetic_to_ecef};

fn sim() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/sim-drive-adis16465")
}

/// Fuses with the shared configuration, `gnss` in place of its GNSS file;
/// returns stdout and the last navresult line.
fn fuse(dir: &Path, name: &str, gnss: &Path, extra: &[&str]) -> (String, Vec<f64>) {
    let yaml = std::fs::read_to_string(sim().join("kf-gins.yaml")).unwrap();
    let out = dir.join(name);
    let yaml = yaml
        .replace("./imu.txt", &sim().join("imu.txt").display().to_string())
        .replace("./gnss.txt", &gnss.display().to_string())
        .replace("./out", &out.display().to_string());
    let cfg = dir.join(format!("{name}.yaml"));
    std::fs::write(&cfg, yaml).unwrap();
    let o = bin()
        .args(["fuse", "--config"])
        .arg(&cfg)
        .args(extra)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert!(o.status.success(), "{stdout}{stderr}");
    let nav = std::fs::read_to_string(out.join("navresult.nav")).unwrap();
    let last = nav.lines().last().unwrap();
    (
        stdout + &stderr,
        last.split_ascii_whitespace()
            .map(|x| x.parse().unwrap())
            .collect(),
    )
}

/// The shared gnss.txt's fixes: sow, lat, lon, h, σ n e d.
fn fixes() -> Vec<[f64; 7]> {
    std::fs::read_to_string(sim().join("gnss.txt"))
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l
                .split_ascii_whitespace()
                .map(|x| x.parse().unwrap())
                .collect();
            [v[0], v[1], v[2], v[3], v[4], v[5], v[6]]
        })
        .collect()
}

#[test]
fn rtklib_llh_and_xyz_fuse_like_the_kfgins_file() {
    let dir = temp_dir("fuse");
    let (_, want) = fuse(&dir, "kfgins", &sim().join("gnss.txt"), &[]);

    // llh, week tow; every 10th fix a single solution (Q=5), one bad line.
    let mut llh = String::from(
        "% program   : RTKLIB ver.2.4.3 b34\n%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n",
    );
    let fx = fixes();
    for (k, f) in fx.iter().enumerate() {
        let q = if k % 10 == 9 { 5 } else { 1 };
        writeln!(
            llh,
            "2300 {:.3} {:.12} {:.12} {:.6} {q} 10 {:.6} {:.6} {:.6} 0.0000 0.0000 0.0000 0.00 0.0",
            f[0], f[1], f[2], f[3], f[4], f[5], f[6]
        )
        .unwrap();
        if k == 100 {
            llh.push_str("2300 100101.500 not-a-number\n");
        }
    }
    let pos = dir.join("rtk.pos");
    std::fs::write(&pos, llh).unwrap();
    let (out, got) = fuse(&dir, "llh", &pos, &[]);
    assert!(
        out.contains("read as RTKLIB .pos (by its extension"),
        "{out}"
    );
    assert!(out.contains("599 used"), "{out}");
    assert!(
        out.contains("rtk.pos:104:"),
        "bad line reported with file:line: {out}"
    );
    // Same fixes, same σ: the same trajectory to the printed precision.
    assert_eq!(got[2..5], want[2..5], "{got:?} vs {want:?}");

    // Fix only: the 59 single solutions are dropped and counted.
    let (out, _) = fuse(&dir, "fixonly", &pos, &["--rtklib-max-q", "1"]);
    assert!(out.contains("540 used"), "{out}");
    assert!(
        out.contains("59 RTKLIB solutions with Q > 1 skipped (Q=5: 59)"),
        "{out}"
    );

    // xyz with calendar GPST (2024-02-04 is the Sunday of week 2300), the
    // NED σ turned into a full ECEF covariance with signed square roots.
    let mut xyz = String::from(
        "%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio\n",
    );
    let ssq = |v: f64| v.signum() * v.abs().sqrt();
    for f in &fx {
        let g = Geodetic::from_deg(f[1], f[2], f[3]);
        let r = geodetic_to_ecef(&g);
        let c = c_ne(&g);
        let p = c
            * Matrix3::from_diagonal(&Vector3::new(f[4] * f[4], f[5] * f[5], f[6] * f[6]))
            * c.transpose();
        let sow = f[0] - 86_400.0;
        let (h, m, s) = (
            (sow / 3600.0).floor(),
            ((sow % 3600.0) / 60.0).floor(),
            sow % 60.0,
        );
        writeln!(
            xyz,
            "2024/02/05 {h:02}:{m:02}:{s:06.3} {:.4} {:.4} {:.4} 1 10 {:.6} {:.6} {:.6} {:.6} {:.6} {:.6} 0.00 0.0",
            r.x, r.y, r.z,
            p[(0, 0)].sqrt(), p[(1, 1)].sqrt(), p[(2, 2)].sqrt(),
            ssq(p[(0, 1)]), ssq(p[(1, 2)]), ssq(p[(2, 0)])
        )
        .unwrap();
    }
    let xyz_path = dir.join("rtk-xyz.txt");
    std::fs::write(&xyz_path, xyz).unwrap();
    // Not a .pos name: the format is named explicitly.
    let (out, got) = fuse(&dir, "xyz", &xyz_path, &["--gnss-format", "rtklib"]);
    assert!(out.contains("read as RTKLIB .pos\n"), "{out}");
    assert!(out.contains("599 used"), "{out}");
    let end = Geodetic::from_deg(want[2], want[3], want[4]);
    let d = navsync::earth::ned_offset(&end, &Geodetic::from_deg(got[2], got[3], got[4]));
    // ECEF printed to 0.1 mm and σ to 1 µm: the end point within 1 mm.
    assert!(d.norm() < 1e-3, "{d:?}");
}
