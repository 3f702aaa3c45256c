//! Scoring a navigation solution against a reference trajectory.
//!
//! Errors are solution minus truth, with the truth interpolated to each
//! solution epoch (position and velocity linearly, attitude by quaternion
//! slerp): position in NED metres, velocity in m/s, attitude as roll,
//! pitch and yaw differences (yaw wrapped to ±180°). For each GNSS outage
//! the maximum horizontal and 3D drift inside it are found, then their RMS
//! over outages: the metric of the KF-GINS paper and of Tang, Zhang & Niu 2022 §1.3.3
//! (Niu et al. 2010, "A proposed evaluation standard for the navigation
//! results of MEMS INS/GPS integrated systems").
#![warn(missing_docs)]

use std::path::Path;

use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;

use crate::attitude::{Euler, euler_to_quat, quat_to_euler, wrap_180, wrap_pi};
use crate::earth::{Geodetic, LocalEarth};
use crate::error::{Diagnostics, Error};
use crate::io::kfgins::{NavReader, NavRecord};
use crate::stats::Moments;
use crate::time::{GpsTime, NS_PER_WEEK, OutageWindow};

/// RMS, maximum absolute value and mean of one error component.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct ErrorStats {
    /// Root mean square of the errors (NaN when none were compared).
    pub rms: f64,
    /// Largest absolute error (not the largest signed one).
    pub max: f64,
    /// Mean (signed) error: the bias of the solution.
    pub mean: f64,
}

impl From<&Moments> for ErrorStats {
    fn from(m: &Moments) -> Self {
        ErrorStats {
            rms: m.rms(),
            max: m.max_abs,
            mean: m.mean(),
        }
    }
}

/// Drift inside one outage window.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct OutageDrift {
    /// Start of the outage (GPS seconds of week).
    pub start_sow: f64,
    /// Length of the outage (s).
    pub len_s: f64,
    /// Solution epochs compared inside the outage, both ends included.
    pub epochs: usize,
    /// Largest horizontal position error inside the outage (m).
    pub max_horizontal_m: f64,
    /// Largest 3D position error inside the outage (m).
    pub max_3d_m: f64,
}

/// The scores of a solution.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct EvalReport {
    /// Solution epochs with a truth state to compare against.
    pub epochs_compared: usize,
    /// Solution epochs outside the truth's span or in a truth gap (not
    /// scored).
    pub epochs_without_truth: usize,
    /// North position error (m).
    pub pos_north_m: ErrorStats,
    /// East position error (m).
    pub(crate) pos_east_m: ErrorStats,
    /// Down position error (m).
    pub(crate) pos_down_m: ErrorStats,
    /// Horizontal position error, √(N² + E²) (m).
    pub pos_horizontal_m: ErrorStats,
    /// 3D position error (m).
    pub pos_3d_m: ErrorStats,
    /// North velocity error (m/s).
    pub(crate) vel_north_mps: ErrorStats,
    /// East velocity error (m/s).
    pub(crate) vel_east_mps: ErrorStats,
    /// Down velocity error (m/s).
    pub(crate) vel_down_mps: ErrorStats,
    /// Horizontal velocity error (m/s).
    pub vel_horizontal_mps: ErrorStats,
    /// 3D velocity error (m/s).
    pub vel_3d_mps: ErrorStats,
    /// Roll difference (deg), wrapped to ±180°.
    pub roll_deg: ErrorStats,
    /// Pitch difference (deg).
    pub pitch_deg: ErrorStats,
    /// Yaw difference (deg), wrapped to ±180°.
    pub yaw_deg: ErrorStats,
    /// Drift in each outage window that held at least one compared epoch.
    pub outages: Vec<OutageDrift>,
    /// RMS over outages of the maximum horizontal drift in each (m);
    /// `None` without outages.
    pub outage_rms_max_horizontal_m: Option<f64>,
    /// RMS over outages of the maximum 3D drift in each (m); `None`
    /// without outages.
    pub outage_rms_max_3d_m: Option<f64>,
    /// Largest horizontal drift of any outage (m); `None` without outages.
    pub outage_worst_horizontal_m: Option<f64>,
    /// Largest 3D drift of any outage (m); `None` without outages.
    pub(crate) outage_worst_3d_m: Option<f64>,
}

impl EvalReport {
    /// The error components in display order: (name, unit, statistics).
    pub fn rows(&self) -> [(&'static str, &'static str, ErrorStats); 13] {
        [
            ("position north", "m", self.pos_north_m),
            ("position east", "m", self.pos_east_m),
            ("position down", "m", self.pos_down_m),
            ("position horizontal", "m", self.pos_horizontal_m),
            ("position 3D", "m", self.pos_3d_m),
            ("velocity north", "m/s", self.vel_north_mps),
            ("velocity east", "m/s", self.vel_east_mps),
            ("velocity down", "m/s", self.vel_down_mps),
            ("velocity horizontal", "m/s", self.vel_horizontal_mps),
            ("velocity 3D", "m/s", self.vel_3d_mps),
            ("roll", "deg", self.roll_deg),
            ("pitch", "deg", self.pitch_deg),
            ("yaw", "deg", self.yaw_deg),
        ]
    }
}

/// One epoch's errors (solution minus truth).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpochError {
    /// The solution epoch (in week 0, as seconds of week, when files are
    /// matched by seconds of week).
    pub time: GpsTime,
    /// Position error (m), NED at the truth position.
    pub pos_ned_m: Vector3<f64>,
    /// Velocity error (m/s), NED.
    pub vel_ned_mps: Vector3<f64>,
    /// roll, pitch, yaw differences (deg), yaw wrapped.
    pub att_deg: Vector3<f64>,
}

/// A state of the reference trajectory at some epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthState {
    /// Epoch of the state.
    pub time: GpsTime,
    /// Reference position.
    pub pos: Geodetic,
    /// Reference velocity (m/s), NED.
    pub vel: Vector3<f64>,
    /// Reference attitude, body (FRD) to NED.
    pub(crate) q_nb: UnitQuaternion<f64>,
}

impl From<&NavRecord> for TruthState {
    fn from(r: &NavRecord) -> Self {
        TruthState {
            time: r.time,
            pos: Geodetic::from_deg(r.lat_deg, r.lon_deg, r.h_m),
            vel: Vector3::from(r.vel),
            q_nb: euler_to_quat(&Euler::from_deg(r.att_deg[0], r.att_deg[1], r.att_deg[2])),
        }
    }
}

/// Linear/slerp interpolation between two truth states.
pub(crate) fn interpolate(a: &TruthState, b: &TruthState, t: GpsTime) -> TruthState {
    let span = (b.time - a.time) as f64;
    let u = if span > 0.0 {
        (t - a.time) as f64 / span
    } else {
        0.0
    };
    let lerp = |x: f64, y: f64| x + (y - x) * u;
    TruthState {
        time: t,
        pos: Geodetic::new(
            lerp(a.pos.lat_rad, b.pos.lat_rad),
            // Across the antimeridian the short way round.
            wrap_pi(a.pos.lon_rad + wrap_pi(b.pos.lon_rad - a.pos.lon_rad) * u),
            lerp(a.pos.h_m, b.pos.h_m),
        ),
        vel: a.vel + (b.vel - a.vel) * u,
        q_nb: a.q_nb.slerp(&b.q_nb, u),
    }
}

/// Errors of a solution state against a truth state at the same epoch.
pub(crate) fn epoch_error(
    truth: &TruthState,
    pos: &Geodetic,
    vel: &Vector3<f64>,
    att: &Euler,
) -> EpochError {
    let le = LocalEarth::new(&truth.pos, &truth.vel);
    let te = quat_to_euler(&truth.q_nb);
    EpochError {
        time: truth.time,
        pos_ned_m: le.geodetic_delta_to_ned(
            pos.lat_rad - truth.pos.lat_rad,
            wrap_pi(pos.lon_rad - truth.pos.lon_rad),
            pos.h_m - truth.pos.h_m,
        ),
        vel_ned_mps: vel - truth.vel,
        att_deg: Vector3::new(
            wrap_180((att.roll_rad - te.roll_rad).to_degrees()),
            (att.pitch_rad - te.pitch_rad).to_degrees(),
            wrap_180((att.yaw_rad - te.yaw_rad).to_degrees()),
        ),
    }
}

/// Accumulates epoch errors into an [`EvalReport`].
#[derive(Clone, Debug, Default)]
pub struct Evaluator {
    m: [Moments; 13],
    outages: Vec<(OutageWindow, OutageDrift)>,
    pub(crate) epochs_without_truth: usize,
}

impl Evaluator {
    /// `outages`: the windows in which drift is measured.
    pub fn new(outages: &[OutageWindow]) -> Self {
        Evaluator {
            outages: outages
                .iter()
                .map(|&w| {
                    (
                        w,
                        OutageDrift {
                            start_sow: w.start.sow(),
                            len_s: w.duration_s,
                            epochs: 0,
                            max_horizontal_m: 0.0,
                            max_3d_m: 0.0,
                        },
                    )
                })
                .collect(),
            ..Default::default()
        }
    }

    /// Adds one epoch's errors.
    pub fn push(&mut self, e: &EpochError) {
        let p = e.pos_ned_m;
        let v = e.vel_ned_mps;
        let h = (p.x * p.x + p.y * p.y).sqrt();
        let vals = [
            p.x,
            p.y,
            p.z,
            h,
            p.norm(),
            v.x,
            v.y,
            v.z,
            (v.x * v.x + v.y * v.y).sqrt(),
            v.norm(),
            e.att_deg.x,
            e.att_deg.y,
            e.att_deg.z,
        ];
        for (m, x) in self.m.iter_mut().zip(vals) {
            m.push(x);
        }
        for (w, d) in &mut self.outages {
            let rel = e.time.seconds_since(w.start);
            if (0.0..=w.duration_s).contains(&rel) {
                d.epochs += 1;
                d.max_horizontal_m = d.max_horizontal_m.max(h);
                d.max_3d_m = d.max_3d_m.max(p.norm());
            }
        }
    }

    /// The statistics over the epochs pushed.
    pub fn finish(self) -> EvalReport {
        let m = &self.m;
        let drifts: Vec<OutageDrift> = self
            .outages
            .into_iter()
            .map(|o| o.1)
            .filter(|d| d.epochs > 0)
            .collect();
        let rms = |f: &dyn Fn(&OutageDrift) -> f64| {
            (!drifts.is_empty()).then(|| {
                (drifts.iter().map(|d| f(d).powi(2)).sum::<f64>() / drifts.len() as f64).sqrt()
            })
        };
        let worst = |f: &dyn Fn(&OutageDrift) -> f64| drifts.iter().map(f).reduce(f64::max);
        EvalReport {
            epochs_compared: m[0].n,
            epochs_without_truth: self.epochs_without_truth,
            pos_north_m: (&m[0]).into(),
            pos_east_m: (&m[1]).into(),
            pos_down_m: (&m[2]).into(),
            pos_horizontal_m: (&m[3]).into(),
            pos_3d_m: (&m[4]).into(),
            vel_north_mps: (&m[5]).into(),
            vel_east_mps: (&m[6]).into(),
            vel_down_mps: (&m[7]).into(),
            vel_horizontal_mps: (&m[8]).into(),
            vel_3d_mps: (&m[9]).into(),
            roll_deg: (&m[10]).into(),
            pitch_deg: (&m[11]).into(),
            yaw_deg: (&m[12]).into(),
            outage_rms_max_horizontal_m: rms(&|d| d.max_horizontal_m),
            outage_rms_max_3d_m: rms(&|d| d.max_3d_m),
            outage_worst_horizontal_m: worst(&|d| d.max_horizontal_m),
            outage_worst_3d_m: worst(&|d| d.max_3d_m),
            outages: drifts,
        }
    }
}

/// Parses `"sow:len,sow:len"` outage windows (week from `week`).
pub fn parse_outages(text: &str, week: i64) -> Result<Vec<OutageWindow>, Error> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (s, l) = part
            .split_once(':')
            .ok_or_else(|| Error::Invalid(format!("outage '{part}': expected sow:length")))?;
        let s: f64 = s
            .trim()
            .parse()
            .map_err(|_| Error::Invalid(format!("outage '{part}': bad start '{s}'")))?;
        let l: f64 = l
            .trim()
            .parse()
            .map_err(|_| Error::Invalid(format!("outage '{part}': bad length '{l}'")))?;
        if l <= 0.0 || !(0.0..604800.0).contains(&s) {
            return Err(Error::Invalid(format!(
                "outage '{part}': expected 0 <= sow < 604800 and length > 0"
            )));
        }
        out.push(OutageWindow::new(GpsTime::from_week_sow(week, s), l));
    }
    Ok(out)
}

/// Streams a truth file and interpolates it at increasing epochs. Records
/// are matched by seconds of week when either file has week 0 (KF-GINS
/// writes week 0), and then across a week rollover too: each side counts
/// time from the start of its first week, the two starts placed in the
/// same week.
pub(crate) struct TruthStream {
    reader: NavReader,
    prev: Option<TruthState>,
    next: Option<TruthState>,
    week: Option<i64>,
    /// By seconds of week: the start (ns) of the truth's first week, and
    /// of the week of the first epoch asked for, aligned with it.
    truth_week_start_ns: i64,
    query_week_start_ns: Option<i64>,
    /// Largest truth gap bridged by interpolation (s).
    pub(crate) max_gap_s: f64,
}

impl TruthStream {
    pub(crate) fn open(path: &Path) -> Result<Self, Error> {
        Ok(TruthStream {
            reader: NavReader::open(path)?,
            prev: None,
            next: None,
            week: None,
            truth_week_start_ns: 0,
            query_week_start_ns: None,
            max_gap_s: 1.0,
        })
    }

    fn fetch(&mut self, diag: &mut Diagnostics) -> Result<Option<TruthState>, Error> {
        Ok(self.reader.next_record(diag)?.map(|r| {
            if self.week.is_none() {
                self.week = Some(r.week);
                self.truth_week_start_ns = GpsTime::from_week_ns(r.time.week(), 0).ns();
            }
            TruthState::from(&r)
        }))
    }

    /// Where `t` falls on the truth's time line when matching by seconds
    /// of week: its time since the start of the first asked-for week,
    /// that week taken as the truth's first week, or the one after or
    /// before when the two first epochs are more than half a week apart
    /// (one side starts after a rollover the other crosses).
    fn query_key_ns(&mut self, t: GpsTime, truth_first: Option<GpsTime>) -> i64 {
        let start = *self.query_week_start_ns.get_or_insert_with(|| {
            let own = GpsTime::from_week_ns(t.week(), 0).ns();
            let Some(first) = truth_first else {
                return own;
            };
            let lead = t.ns_of_week() - first.ns_of_week();
            if lead > NS_PER_WEEK / 2 {
                own + NS_PER_WEEK
            } else if lead < -NS_PER_WEEK / 2 {
                own - NS_PER_WEEK
            } else {
                own
            }
        });
        t.ns() - start
    }

    /// The truth at `t`, or `None` when `t` is outside the truth's span or
    /// in a gap longer than `max_gap_s`. Calls must have increasing `t`.
    pub(crate) fn at(
        &mut self,
        t: GpsTime,
        by_sow: bool,
        diag: &mut Diagnostics,
    ) -> Result<Option<TruthState>, Error> {
        if self.next.is_none() {
            self.next = self.fetch(diag)?;
        }
        let (truth_start, query) = if by_sow {
            let first = self.prev.or(self.next).map(|s| s.time);
            (self.truth_week_start_ns, self.query_key_ns(t, first))
        } else {
            (0, t.ns())
        };
        let key = |x: GpsTime| x.ns() - truth_start;
        loop {
            let Some(n) = self.next else {
                return Ok(None);
            };
            if key(n.time) >= query {
                break;
            }
            self.prev = Some(n);
            self.next = self.fetch(diag)?;
        }
        let n = self.next.expect("checked");
        if key(n.time) == query {
            return Ok(Some(TruthState { time: t, ..n }));
        }
        let Some(p) = self.prev else {
            return Ok(None);
        };
        if (key(n.time) - key(p.time)) as f64 * 1e-9 > self.max_gap_s {
            return Ok(None);
        }
        let pk = GpsTime::from_ns(key(p.time));
        let nk = GpsTime::from_ns(key(n.time));
        let mut s = interpolate(
            &TruthState { time: pk, ..p },
            &TruthState { time: nk, ..n },
            GpsTime::from_ns(query),
        );
        s.time = t;
        Ok(Some(s))
    }

    /// Week of the first truth record (reads it if needed).
    pub(crate) fn week(&mut self, diag: &mut Diagnostics) -> Result<Option<i64>, Error> {
        if self.next.is_none() && self.prev.is_none() {
            self.next = self.fetch(diag)?;
        }
        Ok(self.week)
    }
}

/// Scores navigation states as they come (a [`crate::pipeline::NavSink`]'s
/// view) against a truth file, matched by seconds of week.
pub struct TruthScorer {
    truth: TruthStream,
    pub(crate) without_truth: usize,
    pub(crate) diag: Diagnostics,
}

impl TruthScorer {
    /// Opens the truth trajectory file.
    pub fn open(truth_path: &Path) -> Result<Self, Error> {
        Ok(TruthScorer {
            truth: TruthStream::open(truth_path)?,
            without_truth: 0,
            diag: Diagnostics::with_cap(100),
        })
    }

    /// The errors of `nav` (`None`, and counted, where there is no truth).
    /// Calls must have increasing times.
    pub fn score(&mut self, nav: &crate::ins::NavState) -> Result<Option<EpochError>, Error> {
        match self.truth.at(nav.time, true, &mut self.diag)? {
            Some(t) => Ok(Some(epoch_error(&t, &nav.pos, &nav.vel, &nav.euler()))),
            None => {
                self.without_truth += 1;
                Ok(None)
            }
        }
    }
}

/// Scores the navigation file `nav_path` against `truth_path`.
pub fn eval_files(
    truth_path: &Path,
    nav_path: &Path,
    outages: &[OutageWindow],
    diag: &mut Diagnostics,
) -> Result<EvalReport, Error> {
    eval_files_with(truth_path, nav_path, outages, diag, &mut |_, _, _| {})
}

/// [`eval_files`], also handing every compared epoch to `each`: the
/// solution record, the truth interpolated to it and the errors.
pub fn eval_files_with(
    truth_path: &Path,
    nav_path: &Path,
    outages: &[OutageWindow],
    diag: &mut Diagnostics,
    each: &mut dyn FnMut(&NavRecord, &TruthState, &EpochError),
) -> Result<EvalReport, Error> {
    let mut truth = TruthStream::open(truth_path)?;
    let mut nav = NavReader::open(nav_path)?;
    let mut first = true;
    let mut by_sow = false;
    let mut ev: Option<Evaluator> = None;
    while let Some(rec) = nav.next_record(diag)? {
        if first {
            first = false;
            // Match by seconds of week when either side has no week.
            let truth_week = truth.week(diag)?;
            by_sow = rec.week == 0 || truth_week == Some(0);
            // Outage windows are given in sow: place each in the solution's
            // first week, or the next when it starts more than half a week
            // before the first epoch (after a rollover).
            let first_week = rec.time.week();
            let first_ns = rec.time.ns_of_week();
            let o: Vec<OutageWindow> = outages
                .iter()
                .map(|w| {
                    let ns = w.start.ns_of_week();
                    let week = first_week + i64::from(ns + NS_PER_WEEK / 2 < first_ns);
                    OutageWindow::new(GpsTime::from_week_ns(week, ns), w.duration_s)
                })
                .collect();
            ev = Some(Evaluator::new(&o));
        }
        let e = ev.as_mut().expect("set on first record");
        match truth.at(rec.time, by_sow, diag)? {
            Some(ts) => {
                let pos = Geodetic::from_deg(rec.lat_deg, rec.lon_deg, rec.h_m);
                let att = Euler::from_deg(rec.att_deg[0], rec.att_deg[1], rec.att_deg[2]);
                let err = epoch_error(&ts, &pos, &Vector3::from(rec.vel), &att);
                e.push(&err);
                each(&rec, &ts, &err);
            }
            None => e.epochs_without_truth += 1,
        }
    }
    let ev = ev.ok_or_else(|| Error::NoData {
        path: nav_path.to_path_buf(),
        msg: "no navigation records".into(),
    })?;
    let report = ev.finish();
    if report.epochs_compared == 0 {
        return Err(Error::NoData {
            path: nav_path.to_path_buf(),
            msg: format!("no epoch overlaps the truth in {}", truth_path.display()),
        });
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_error_wraps() {
        let t = TruthState {
            time: GpsTime::EPOCH,
            pos: Geodetic::from_deg(30.0, 114.0, 10.0),
            vel: Vector3::zeros(),
            q_nb: euler_to_quat(&Euler::from_deg(0.0, 0.0, 179.9)),
        };
        let e = epoch_error(&t, &t.pos, &t.vel, &Euler::from_deg(0.0, 0.0, -179.9));
        assert!((e.att_deg.z - 0.2).abs() < 1e-9, "{}", e.att_deg.z);
    }

    /// Truth and solution on either side of the antimeridian: the east
    /// error is the short way round, and interpolation does not sweep
    /// the globe.
    #[test]
    fn longitude_across_the_antimeridian() {
        let state = |sow: f64, lon: f64| TruthState {
            time: GpsTime::from_week_sow(0, sow),
            pos: Geodetic::from_deg(0.0, lon, 0.0),
            vel: Vector3::zeros(),
            q_nb: euler_to_quat(&Euler::from_deg(0.0, 0.0, 90.0)),
        };
        // 1e-5° of longitude at the equator: 1.113 m east.
        let east_per_step = 1e-5f64.to_radians() * 6_378_137.0;
        let (a, b) = (state(0.0, 179.999_995), state(1.0, -179.999_995));
        let mid = interpolate(&a, &b, GpsTime::from_week_sow(0, 0.5));
        assert!(
            (wrap_pi(mid.pos.lon_rad - std::f64::consts::PI)).abs() < 1e-12,
            "{}",
            mid.pos.lon_rad.to_degrees()
        );
        let e = epoch_error(&a, &b.pos, &a.vel, &Euler::from_deg(0.0, 0.0, 90.0));
        assert!(
            (e.pos_ned_m.y - east_per_step).abs() < 1e-3,
            "{}",
            e.pos_ned_m.y
        );
    }

    #[test]
    fn outage_drift_and_rms() {
        let s = GpsTime::from_week_sow(0, 100.0);
        let mut ev = Evaluator::new(&[
            OutageWindow::new(s, 10.0),
            OutageWindow::new(s.add_seconds(100.0), 10.0),
        ]);
        for k in 0..300 {
            let t = GpsTime::from_week_sow(0, 90.0 + k as f64);
            let in1 = (100.0..=110.0).contains(&(90.0 + k as f64));
            let in2 = (200.0..=210.0).contains(&(90.0 + k as f64));
            let err = if in1 {
                3.0
            } else if in2 {
                4.0
            } else {
                0.1
            };
            ev.push(&EpochError {
                time: t,
                pos_ned_m: Vector3::new(err, 0.0, 0.0),
                vel_ned_mps: Vector3::zeros(),
                att_deg: Vector3::zeros(),
            });
        }
        let r = ev.finish();
        assert_eq!(r.outages.len(), 2);
        assert_eq!(r.outages[0].max_horizontal_m, 3.0);
        assert!((r.outage_rms_max_horizontal_m.unwrap() - (12.5f64).sqrt()).abs() < 1e-12);
        assert_eq!(r.outage_worst_horizontal_m, Some(4.0));
    }

    #[test]
    fn outage_argument_parsing() {
        let o = parse_outages("100120.005:60, 100300:60", 2300).unwrap();
        assert_eq!(o.len(), 2);
        assert_eq!(o[0].duration_s, 60.0);
        assert!(parse_outages("100120", 0).is_err());
        assert!(parse_outages("1:-5", 0).is_err());
    }

    /// Writes an 11-column nav file: `(week, sow, east offset m)` per line,
    /// on a meridian at 30° N moving east.
    fn write_nav(path: &Path, rows: &[(i64, f64, f64)]) {
        let mut text = String::new();
        for (week, sow, east_m) in rows {
            let lon = 114.0 + east_m / 96_486.0;
            text.push_str(&format!(
                "{week} {sow:.3} 30.0 {lon:.12} 20.0 0 1 0 0 0 90\n"
            ));
        }
        std::fs::write(path, text).unwrap();
    }

    #[test]
    fn a_drive_across_the_week_rollover_is_scored_whole() {
        let dir = crate::testfiles::TestDir::new("eval-rollover");
        // 1 Hz from 604790 s of week 2300 to 10 s into week 2301.
        let secs: Vec<f64> = (0..=20).map(|k| 604_790.0 + k as f64).collect();
        let sow = |t: f64| if t >= 604_800.0 { t - 604_800.0 } else { t };
        let truth = dir.join("truth.nav");
        let with_weeks: Vec<_> = secs
            .iter()
            .map(|&t| {
                (
                    if t >= 604_800.0 { 2301 } else { 2300 },
                    sow(t),
                    t - 604_790.0,
                )
            })
            .collect();
        write_nav(&truth, &with_weeks);
        // The solution as KF-GINS writes it: week 0, seconds of week wrapping;
        // 1 m east of the truth from 604 805 s (5 s after the rollover).
        let nav = dir.join("nav.nav");
        let rows: Vec<_> = secs
            .iter()
            .map(|&t| {
                (
                    0,
                    sow(t),
                    t - 604_790.0 + if t >= 604_805.0 { 1.0 } else { 0.0 },
                )
            })
            .collect();
        write_nav(&nav, &rows);
        let mut diag = Diagnostics::default();
        let outage = parse_outages("5:3", 0).unwrap();
        let r = eval_files(&truth, &nav, &outage, &mut diag).unwrap();
        assert!(diag.is_empty(), "{diag:?}");
        assert_eq!(r.epochs_compared, 21);
        assert_eq!(r.epochs_without_truth, 0);
        // Six epochs (604 805..=604 810) 1 m off.
        assert!(
            (r.pos_horizontal_m.max - 1.0).abs() < 1e-3,
            "{:?}",
            r.pos_horizontal_m
        );
        assert!((r.pos_horizontal_m.rms - (6.0f64 / 21.0).sqrt()).abs() < 1e-3);
        // The window at 5 s of week is after the rollover, not 604 795 s
        // before it: it sees the 1 m error.
        assert_eq!(r.outages.len(), 1);
        assert_eq!(r.outages[0].epochs, 4);
        assert!((r.outages[0].max_horizontal_m - 1.0).abs() < 1e-3);

        // The truth may start after the rollover the solution crosses.
        write_nav(&truth, &with_weeks[12..]);
        let r = eval_files(&truth, &nav, &[], &mut diag).unwrap();
        assert_eq!(r.epochs_compared, 9);
        assert_eq!(r.epochs_without_truth, 12);

        // A time far back in mid-week is a bad line, not a new week: it is
        // reported and the rest of the file is kept.
        let mut bad = rows[..5].to_vec();
        bad.push((0, 1000.0, 0.0));
        bad.extend_from_slice(&rows[5..]);
        write_nav(&nav, &bad);
        let mut diag = Diagnostics::default();
        let r = eval_files(&truth, &nav, &[], &mut diag).unwrap();
        assert_eq!(r.epochs_compared, 9);
        assert_eq!(diag.total, 1, "{diag:?}");
        assert_eq!(diag.items[0].line, 6);
        assert!(
            diag.items[0].message.contains("time goes backwards"),
            "{diag:?}"
        );
    }
}
