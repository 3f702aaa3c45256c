//! Inputs of `navsync track` that come from files or presets: the
//! receiver trajectory (static, generated land vehicle, or a navigation
//! file) and aiding-error schedules (a preset whose quality changes over
//! time, or the velocity covariance of a navsync fusion run).

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::aiding::{AidingErrorConfig, AidingSegment, AidingStats};
use super::dynamics::{
    GeodeticSample, LandVehicleOptions, LandVehicleProfile, SampledTrajectory, StaticTrajectory,
    Trajectory,
};
use navsync::earth::Geodetic;
use navsync::error::{Diagnostics, Error};
use navsync::io::kfgins::NavReader;
use navsync::io::text::{LineReader, is_blank_or_comment, parse_f64, split_fields};

/// Where the receiver goes.
#[derive(Clone, Debug, PartialEq)]
pub enum Scenario {
    Static,
    /// The generated land-vehicle drive (jerk ≤ 1 g/s).
    Land(LandVehicleOptions),
    /// A navigation or truth file (KF-GINS 11-column layout, e.g. a
    /// `navsync fuse` result or a simulator's truth).
    NavFile(PathBuf),
}

/// Builds the trajectory of a scenario.
pub fn trajectory(s: &Scenario, diag: &mut Diagnostics) -> Result<Box<dyn Trajectory>, Error> {
    Ok(match s {
        Scenario::Static => Box::new(StaticTrajectory),
        Scenario::Land(o) => Box::new(LandVehicleProfile::new(o)),
        Scenario::NavFile(p) => Box::new(nav_file_trajectory(p, diag)?),
    })
}

/// Reads an 11-column navigation file into a [`SampledTrajectory`].
pub(crate) fn nav_file_trajectory(
    path: &Path,
    diag: &mut Diagnostics,
) -> Result<SampledTrajectory, Error> {
    let recs = NavReader::read_all(path, diag)?;
    let samples: Vec<GeodeticSample> = recs
        .iter()
        .map(|r| GeodeticSample {
            t_s: r.time.seconds(),
            pos: Geodetic::from_deg(r.lat_deg, r.lon_deg, r.h_m),
            vel_ned_mps: Vector3::from(r.vel),
        })
        .collect();
    SampledTrajectory::from_geodetic(&samples).map_err(|m| Error::NoData {
        path: path.to_path_buf(),
        msg: m,
    })
}

/// Reads the NED velocity standard deviations (columns 5–7, m/s) of a
/// KF-GINS/navsync `std.txt` and projects them on the line of sight
/// `unit_ned` (σ² = Σ u_i² σ_i², cross-covariances unknown): returns
/// `(seconds since the first line, σ_los)`. Bad lines are reported and
/// skipped.
pub fn read_los_velocity_sd(
    path: &Path,
    unit_ned: &Vector3<f64>,
    diag: &mut Diagnostics,
) -> Result<Vec<(f64, f64)>, Error> {
    let mut lines = LineReader::open(path)?;
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut t0 = None;
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 7] = [b""; 7];
        let n = split_fields(line, &mut f);
        if n < 7 {
            diag.push(path, no, format!("expected at least 7 fields (sow, 3 position σ, 3 velocity σ), found {n}; line skipped"));
            continue;
        }
        let vals: Result<Vec<f64>, String> = f.iter().map(|x| parse_f64(x)).collect();
        let v = match vals {
            Ok(v) => v,
            Err(e) => {
                diag.push(path, no, format!("{e}; line skipped"));
                continue;
            }
        };
        let t = v[0] - *t0.get_or_insert(v[0]);
        if out.last().is_some_and(|l| t <= l.0) {
            diag.push(path, no, "time does not increase; line skipped");
            continue;
        }
        let sd = (0..3)
            .map(|i| (unit_ned[i] * v[4 + i]).powi(2))
            .sum::<f64>()
            .sqrt();
        out.push((t, sd));
    }
    if out.is_empty() {
        return Err(Error::NoData {
            path: path.to_path_buf(),
            msg: "no standard-deviation lines (expected `sow sd_pn sd_pe sd_pd sd_vn sd_ve sd_vd ...`)".into(),
        });
    }
    Ok(out)
}

/// Aiding of good quality (GNSS updates every second): 0.03 Hz held GM
/// (τ = 5 s) and a 0.02 Hz/s ramp reset at each update.
pub const AIDING_GOOD: AidingStats = AidingStats {
    ramp_hz_s: 0.02,
    gm_sd_hz: 0.03,
    gm_tau_s: 5.0,
    update_period_s: 1.0,
};

/// Aiding of poor quality (as in a GNSS outage: corrections every 5 s, a
/// steeper ramp and a larger, faster GM error).
pub const AIDING_POOR: AidingStats = AidingStats {
    ramp_hz_s: 0.3,
    gm_sd_hz: 0.3,
    gm_tau_s: 2.0,
    update_period_s: 5.0,
};

/// A schedule alternating [`AIDING_GOOD`] and [`AIDING_POOR`] every
/// `period_s` seconds up to `duration_s`.
pub fn varying_aiding(period_s: f64, duration_s: f64) -> AidingErrorConfig {
    let mut segs = Vec::new();
    let mut t = 0.0;
    let mut good = true;
    while t < duration_s {
        segs.push(AidingSegment {
            start_s: t,
            stats: if good { AIDING_GOOD } else { AIDING_POOR },
        });
        good = !good;
        t += period_s;
    }
    AidingErrorConfig::Schedule(segs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn std_file_is_projected_and_bad_lines_skipped() {
        let dir = navsync::testfiles::TestDir::new("track-std");
        let p = dir.join("std.txt");
        std::fs::write(
            &p,
            "# comment\n100.0 1 1 1 0.03 0.04 0.0 9\n100.5 1 1\n101.0 1 1 1 x 0 0\n101.0 1 1 1 0.06 0.08 0.5\n",
        )
        .unwrap();
        let mut d = Diagnostics::default();
        let u = Vector3::new(0.6, 0.8, 0.0);
        let s = read_los_velocity_sd(&p, &u, &mut d).unwrap();
        assert_eq!(s.len(), 2);
        assert!((s[0].1 - (0.018f64.powi(2) + 0.032f64.powi(2)).sqrt()).abs() < 1e-12);
        assert_eq!(s[1].0, 1.0);
        assert_eq!(d.total, 2, "{:?}", d.items);
        assert!(d.items[0].to_string().contains(":3:"), "{}", d.items[0]);
        std::fs::write(&p, "# nothing\n").unwrap();
        assert!(read_los_velocity_sd(&p, &u, &mut d).is_err());
    }

    #[test]
    fn varying_schedule_alternates() {
        let AidingErrorConfig::Schedule(s) = varying_aiding(30.0, 100.0) else {
            panic!("schedule expected")
        };
        assert_eq!(s.len(), 4);
        assert_eq!(s[1].stats, AIDING_POOR);
        assert_eq!(s[2].start_s, 60.0);
    }
}
