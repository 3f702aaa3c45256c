//! The written solution judged as it is: the file the verdict is about
//! (a smoothed `navresult.nav`, or the forward filter's) against the GNSS
//! fixes, against the forward filter it was smoothed from, and its own σ
//! and speeds. The filter's statistics (innovations, NIS, σ) describe the
//! forward pass; a smoother that diverged after it (a heading σ of 180°
//! carried into position) leaves them all "good". These checks catch it.

use std::path::Path;

use navsync::earth::Geodetic;
use navsync::error::{Diagnostics, Error};
use navsync::io::kfgins::{GnssLayout, GnssReader, NavReader};

use navsync::earth::ned_offset;

/// A solution file's horizontal track about an origin.
#[derive(Clone, Debug, Default)]
pub(crate) struct Track {
    pub sow: Vec<f64>,
    pub ne: Vec<(f64, f64)>,
    pub speed_mps: Vec<f64>,
    /// Velocity north, east (m/s) and roll, pitch, yaw (rad).
    pub vel_ne_mps: Vec<[f64; 2]>,
    pub att_rad: Vec<[f64; 3]>,
}

impl Track {
    /// Reads `path` (11-column navigation file) about `origin`.
    pub(crate) fn read(
        path: &Path,
        origin: &Geodetic,
        diag: &mut Diagnostics,
    ) -> Result<Self, Error> {
        let mut r = NavReader::open(path)?;
        let mut t = Track::default();
        while let Some(rec) = r.next_record(diag)? {
            let d = ned_offset(
                origin,
                &Geodetic::from_deg(rec.lat_deg, rec.lon_deg, rec.h_m),
            );
            t.sow.push(rec.time.sow());
            t.ne.push((d.x, d.y));
            t.speed_mps.push(rec.vel[0].hypot(rec.vel[1]));
            t.vel_ne_mps.push([rec.vel[0], rec.vel[1]]);
            t.att_rad.push(rec.att_deg.map(f64::to_radians));
        }
        Ok(t)
    }

    /// The horizontal position at `sow`, linearly interpolated; `None`
    /// outside the track or across a gap longer than `max_gap_s`.
    pub(crate) fn at(&self, sow: f64, max_gap_s: f64) -> Option<(f64, f64)> {
        let k = self.sow.partition_point(|&t| t < sow);
        if k == 0 || k >= self.sow.len() {
            return (self.sow.get(k) == Some(&sow)).then(|| self.ne[k]);
        }
        let (t0, t1) = (self.sow[k - 1], self.sow[k]);
        if t1 - t0 > max_gap_s {
            return None;
        }
        let u = if t1 > t0 { (sow - t0) / (t1 - t0) } else { 0.0 };
        let (a, b) = (self.ne[k - 1], self.ne[k]);
        Some((a.0 + u * (b.0 - a.0), a.1 + u * (b.1 - a.1)))
    }

    /// The index of the epoch nearest `sow`, if one is within `max_s`.
    pub(crate) fn nearest(&self, sow: f64, max_s: f64) -> Option<usize> {
        let k = self.sow.partition_point(|&t| t < sow);
        [k.checked_sub(1), Some(k)]
            .into_iter()
            .flatten()
            .filter(|&i| i < self.sow.len() && (self.sow[i] - sow).abs() <= max_s)
            .min_by(|&a, &b| {
                (self.sow[a] - sow)
                    .abs()
                    .total_cmp(&(self.sow[b] - sow).abs())
            })
    }

    /// The median roll and pitch (rad): the IMU's usual tilt, from which
    /// gravity's direction in its axes follows.
    pub(crate) fn median_roll_pitch_rad(&self) -> Option<[f64; 2]> {
        let med = |i: usize| {
            let mut v: Vec<f64> = self
                .att_rad
                .iter()
                .map(|a| a[i])
                .filter(|x| x.is_finite())
                .collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied()
        };
        Some([med(0)?, med(1)?])
    }
}

/// A GNSS fix: seconds of week, north/east about the origin (m), stated
/// horizontal σ (m).
#[derive(Clone, Copy, Debug)]
pub(crate) struct FixPoint {
    pub sow: f64,
    pub ne: (f64, f64),
    pub sd_h_m: f64,
}

/// Reads a KF-GINS GNSS file about `origin`.
pub(crate) fn read_fixes(
    path: &Path,
    origin: &Geodetic,
    diag: &mut Diagnostics,
) -> Result<Vec<FixPoint>, Error> {
    let mut r = GnssReader::open(path, 0, GnssLayout::Cpp)?;
    let mut out = Vec::new();
    while let Some(f) = r.next_fix(diag)? {
        let d = ned_offset(origin, &f.pos);
        out.push(FixPoint {
            sow: f.time.sow(),
            ne: (d.x, d.y),
            sd_h_m: f.pos_sd.x.hypot(f.pos_sd.y),
        });
    }
    Ok(out)
}

/// What the written file says against the fixes and the forward pass.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct WrittenEvidence {
    /// Fixes inside the written solution's span.
    pub fixes_compared: usize,
    /// All fixes read.
    pub fixes_total: usize,
    /// Horizontal RMS of (solution − fix) at the fixes (m). The solution
    /// is the IMU centre, the fix the antenna: a lever arm adds to it.
    pub rms_vs_fixes_m: f64,
    /// Median stated horizontal σ of the fixes (m).
    pub median_fix_sd_h_m: f64,
    /// The forward filter's RMS against the same fixes, when the written
    /// file is a smoothed one.
    pub forward_rms_vs_fixes_m: Option<f64>,
    /// Largest horizontal speed in the written file and in the fixes'
    /// track (m/s).
    pub max_speed_mps: f64,
    pub max_fix_speed_mps: f64,
    /// Largest horizontal σ written (m).
    pub max_sd_h_m: Option<f64>,
}

/// RMS of the horizontal distance between `track` and the fixes it spans.
fn rms_against(track: &Track, fixes: &[FixPoint], max_gap_s: f64) -> (usize, f64) {
    let (n, ss) = fixes
        .iter()
        .filter_map(|f| {
            track
                .at(f.sow, max_gap_s)
                .map(|p| (p.0 - f.ne.0).powi(2) + (p.1 - f.ne.1).powi(2))
        })
        .fold((0usize, 0.0), |(n, s), d| (n + 1, s + d));
    (
        n,
        if n > 0 {
            (ss / n as f64).sqrt()
        } else {
            f64::NAN
        },
    )
}

/// The evidence, from the written track, the forward one (if smoothed),
/// the fixes and the written σ (std.txt rows: sow, σ_n, σ_e, …).
pub(crate) fn evidence(
    written: &Track,
    forward: Option<&Track>,
    fixes: &[FixPoint],
    std: Option<&[Vec<f64>]>,
) -> Option<WrittenEvidence> {
    if written.sow.len() < 2 || fixes.len() < 2 {
        return None;
    }
    // Interpolate only across the output's own spacing (an IMU-rate file),
    // never across a hole of several seconds.
    let max_gap_s = 2.0;
    let (n, rms) = rms_against(written, fixes, max_gap_s);
    if n == 0 {
        return None;
    }
    let mut sd: Vec<f64> = fixes.iter().map(|f| f.sd_h_m).collect();
    sd.sort_by(f64::total_cmp);
    let max_fix_speed_mps = fixes
        .windows(2)
        .filter(|w| w[1].sow - w[0].sow > 0.05)
        .map(|w| (w[1].ne.0 - w[0].ne.0).hypot(w[1].ne.1 - w[0].ne.1) / (w[1].sow - w[0].sow))
        .fold(0.0, f64::max);
    Some(WrittenEvidence {
        fixes_compared: n,
        fixes_total: fixes.len(),
        rms_vs_fixes_m: rms,
        median_fix_sd_h_m: sd[sd.len() / 2],
        forward_rms_vs_fixes_m: forward.map(|f| rms_against(f, fixes, max_gap_s).1),
        max_speed_mps: written.speed_mps.iter().copied().fold(0.0, f64::max),
        max_fix_speed_mps,
        max_sd_h_m: std.map(|rows| {
            rows.iter()
                .map(|r| r[1].hypot(r[2]))
                .fold(
                    0.0,
                    |a: f64, b| if b.is_nan() { f64::INFINITY } else { a.max(b) },
                )
        }),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn track(points: &[(f64, f64, f64)]) -> Track {
        Track {
            sow: points.iter().map(|p| p.0).collect(),
            ne: points.iter().map(|p| (p.1, p.2)).collect(),
            speed_mps: vec![1.0; points.len()],
            vel_ne_mps: vec![[1.0, 0.0]; points.len()],
            att_rad: vec![[0.0; 3]; points.len()],
        }
    }

    #[test]
    fn interpolates_inside_and_refuses_outside_and_across_holes() {
        let t = track(&[(10.0, 0.0, 0.0), (11.0, 2.0, 4.0), (20.0, 0.0, 0.0)]);
        assert_eq!(t.at(10.5, 2.0), Some((1.0, 2.0)));
        assert_eq!(t.at(10.0, 2.0), Some((0.0, 0.0)));
        assert_eq!(t.at(9.0, 2.0), None);
        assert_eq!(t.at(15.0, 2.0), None);
        assert_eq!(t.at(21.0, 2.0), None);
        assert_eq!(t.nearest(10.6, 0.5), Some(1));
        assert_eq!(t.nearest(10.4, 0.5), Some(0));
        assert_eq!(t.nearest(15.0, 0.5), None);
        assert_eq!(t.nearest(25.0, 10.0), Some(2));
    }

    #[test]
    fn a_track_off_the_fixes_is_measured_so() {
        let fixes: Vec<FixPoint> = (0..10)
            .map(|k| FixPoint {
                sow: k as f64,
                ne: (k as f64, 0.0),
                sd_h_m: 1.0,
            })
            .collect();
        let on = track(
            &(0..10)
                .map(|k| (k as f64, k as f64, 0.0))
                .collect::<Vec<_>>(),
        );
        let off = track(
            &(0..10)
                .map(|k| (k as f64, k as f64, 300.0))
                .collect::<Vec<_>>(),
        );
        let e = evidence(&off, Some(&on), &fixes, None).unwrap();
        assert!((e.rms_vs_fixes_m - 300.0).abs() < 1e-9);
        assert_eq!(e.forward_rms_vs_fixes_m, Some(0.0));
        assert_eq!(e.fixes_compared, 10);
        assert!((e.max_fix_speed_mps - 1.0).abs() < 1e-9);
    }
}
