//! GNSS faults injected into any KF-GINS GNSS file, with labels.
//!
//! The fault classes real receivers produce, as issue 33 ("GNSS
//! integrity") lists them: a single spike, a false RTK fix (a wrong
//! integer ambiguity fix: a constant offset while the receiver still
//! states RTK-level σ; Teunissen & Verhagen, "The GNSS ambiguity
//! ratio-test revisited", GPS Solutions 2009), a slowly building ramp
//! (multipath growing as the geometry changes; Groves, *Principles of
//! GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed.,
//! 2013, ch. 9 and 17) and a stale position repeated with new times.
//!
//! The file is read line by line (FORMATS.md §1: `sow lat_deg lon_deg h_m
//! …`, 7 or 13 fields); only the faulty lines are rewritten, every other
//! line is copied byte for byte. A faulty line keeps its time, σ and
//! velocity columns (the σ of a false fix stays at RTK level: that is what
//! makes it dangerous); only latitude, longitude and height change (a
//! stale line repeats the whole previous line with its own time). Each
//! label is the NED offset of the written position from the original one,
//! computed exactly through ECEF from the numbers as written.
//!
//! Sizes, durations, directions and placements are drawn from the seed
//! (one [`rng::stream`] per purpose) within [`FaultRanges`]; episodes never
//! overlap (at least `min_separation_s` apart), never start in the first
//! `skip_start_s` and never straddle a gap in the fixes.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use navsync::earth::{Geodetic, c_ne, ecef_to_geodetic, geodetic_to_ecef, ned_offset};
use navsync::io::kfgins::TextWriter;
use navsync::io::text::{is_blank_or_comment, parse_f64, parse_seconds_ns, split_fields};
use navsync::{Diagnostics, Error};
use serde::Serialize;

use crate::rng::{self, SimRng};

/// A class of receiver fault.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultClass {
    /// One fix off by tens of metres (a corrupt solution, a multipath or
    /// cycle-slip outlier).
    Spike,
    /// A wrong RTK ambiguity fix: a constant offset for several seconds,
    /// stated σ unchanged.
    FalseFix,
    /// An offset growing linearly to its peak (building multipath), then
    /// gone.
    Ramp,
    /// The last good position repeated with new times.
    Stale,
}

impl FaultClass {
    /// Every class, in the order of the issue.
    pub const ALL: [FaultClass; 4] = [
        FaultClass::Spike,
        FaultClass::FalseFix,
        FaultClass::Ramp,
        FaultClass::Stale,
    ];

    /// The class's name in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            FaultClass::Spike => "spike",
            FaultClass::FalseFix => "false-fix",
            FaultClass::Ramp => "ramp",
            FaultClass::Stale => "stale",
        }
    }

    /// The class named `s`.
    pub fn parse(s: &str) -> Result<FaultClass, String> {
        FaultClass::ALL
            .into_iter()
            .find(|c| c.name() == s.trim())
            .ok_or_else(|| {
                format!("unknown fault class '{s}' (expected spike, false-fix, ramp or stale)")
            })
    }

    /// What the class models (the labels' header).
    fn models(self, r: &FaultRanges) -> String {
        match self {
            FaultClass::Spike => format!(
                "one fix off by {}–{} m (3D, elevation within ±{}°): a corrupt solution or a multipath/cycle-slip outlier",
                r.spike_m[0], r.spike_m[1], r.max_elevation_deg
            ),
            FaultClass::FalseFix => format!(
                "a constant {}–{} m offset for {}–{} s with the stated σ unchanged (RTK level): a wrong integer ambiguity fix (Teunissen & Verhagen, \"The GNSS ambiguity ratio-test revisited\", GPS Solutions 2009)",
                r.false_fix_m[0], r.false_fix_m[1], r.false_fix_s[0], r.false_fix_s[1]
            ),
            FaultClass::Ramp => format!(
                "an offset growing linearly to {}–{} m over {}–{} s, then gone: slowly building multipath (Groves, Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems, 2nd ed., ch. 9)",
                r.ramp_m[0], r.ramp_m[1], r.ramp_s[0], r.ramp_s[1]
            ),
            FaultClass::Stale => format!(
                "the last good line repeated (position, σ, velocity) with new times for {}–{} s: a receiver re-sending its last solution",
                r.stale_s[0], r.stale_s[1]
            ),
        }
    }
}

/// The ranges every drawn parameter lies in ([lo, hi]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaultRanges {
    /// Spike size, 3D norm (m).
    pub spike_m: [f64; 2],
    /// False fix offset, 3D norm (m).
    pub false_fix_m: [f64; 2],
    /// False fix duration (s).
    pub false_fix_s: [f64; 2],
    /// Ramp peak, 3D norm (m).
    pub ramp_m: [f64; 2],
    /// Ramp duration (s).
    pub ramp_s: [f64; 2],
    /// Stale repeat duration (s).
    pub stale_s: [f64; 2],
    /// Offsets' elevation drawn uniform in ±this (deg; azimuth uniform).
    pub max_elevation_deg: f64,
}

impl FaultRanges {
    /// Why these ranges are unusable (a bound negative, not finite or
    /// above its limit, lo > hi, a duration of zero), or `None`.
    pub fn problem(&self) -> Option<String> {
        let pairs = [
            ("spike size (m)", self.spike_m, 1e4),
            ("false-fix offset (m)", self.false_fix_m, 1e4),
            ("false-fix duration (s)", self.false_fix_s, 3600.0),
            ("ramp peak (m)", self.ramp_m, 1e4),
            ("ramp duration (s)", self.ramp_s, 3600.0),
            ("stale duration (s)", self.stale_s, 3600.0),
        ];
        for (what, [lo, hi], max) in pairs {
            if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi && hi <= max) {
                return Some(format!(
                    "{what} range [{lo}, {hi}]: expected 0 ≤ lo ≤ hi ≤ {max}"
                ));
            }
        }
        for (what, [_, hi]) in [
            ("false-fix", self.false_fix_s),
            ("ramp", self.ramp_s),
            ("stale", self.stale_s),
        ] {
            if hi <= 0.0 {
                return Some(format!(
                    "{what} duration range ends at {hi} s: expected a positive duration"
                ));
            }
        }
        if !(0.0..=90.0).contains(&self.max_elevation_deg) {
            return Some(format!(
                "elevation limit {}°: expected 0–90°",
                self.max_elevation_deg
            ));
        }
        None
    }
}

impl Default for FaultRanges {
    /// Issue 33's figures: spikes 15–50 m, false fixes 0.5–10 m for
    /// 8–15 s, ramps to ~1.5 m over ~20 s, stale repeats of a few seconds.
    fn default() -> Self {
        FaultRanges {
            spike_m: [15.0, 50.0],
            false_fix_m: [0.5, 10.0],
            false_fix_s: [8.0, 15.0],
            ramp_m: [1.0, 2.0],
            ramp_s: [15.0, 25.0],
            stale_s: [3.0, 10.0],
            max_elevation_deg: 30.0,
        }
    }
}

/// One planned episode (a line of a plan file).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlanEntry {
    /// The class.
    pub class: FaultClass,
    /// Time of the first faulty fix (s of week; must be a fix's time).
    pub start_sow: f64,
    /// Duration (s; a spike is one fix whatever it says).
    pub duration_s: f64,
    /// The offset (peak for a ramp), NED (m); drawn when absent; none for
    /// a stale repeat.
    pub offset_ned_m: Option<[f64; 3]>,
    /// The plan file's line.
    pub line: usize,
}

/// What to inject.
#[derive(Clone, Debug, Serialize)]
pub struct FaultOptions {
    /// The run's seed.
    pub seed: u64,
    /// The classes, cycled over the episodes.
    pub classes: Vec<FaultClass>,
    /// How many episodes (ignored with a plan).
    pub count: usize,
    /// The parameter ranges.
    pub ranges: FaultRanges,
    /// No episode starts within this of the first fix (s): the filter's
    /// convergence is not the test.
    pub skip_start_s: f64,
    /// Clean time between episodes (s).
    pub min_separation_s: f64,
    /// Explicit episodes instead of drawn placements.
    pub plan: Option<Plan>,
}

/// A plan file's episodes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Plan {
    /// The plan file (for errors).
    pub path: PathBuf,
    /// Its episodes, in file order.
    pub entries: Vec<PlanEntry>,
}

impl Default for FaultOptions {
    fn default() -> Self {
        FaultOptions {
            seed: 1,
            classes: FaultClass::ALL.to_vec(),
            count: 4,
            ranges: FaultRanges::default(),
            skip_start_s: 60.0,
            min_separation_s: 20.0,
            plan: None,
        }
    }
}

/// One injected episode.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Episode {
    /// 1-based, in time order.
    pub episode: usize,
    /// The class.
    pub class: FaultClass,
    /// Time of the first and last faulty fix (s of week).
    pub first_sow: f64,
    /// Time of the last faulty fix.
    pub last_sow: f64,
    /// Faulty fixes.
    pub fixes: usize,
    /// The drawn or planned duration (s).
    pub duration_s: f64,
    /// The drawn or planned offset (a ramp's peak), NED (m); for a stale
    /// repeat the largest written offset.
    pub offset_ned_m: [f64; 3],
}

/// One faulty fix.
#[derive(Clone, Debug, PartialEq)]
pub struct Label {
    /// The fix's time as written in the file.
    pub sow_text: String,
    /// The same, in seconds.
    pub sow: f64,
    /// The class.
    pub class: FaultClass,
    /// Its episode (1-based).
    pub episode: usize,
    /// Written minus original position, NED (m).
    pub offset_ned_m: [f64; 3],
}

/// The result of an injection.
#[derive(Debug)]
pub struct Injection {
    /// The faulty file's bytes.
    pub text: Vec<u8>,
    /// The episodes, in time order.
    pub episodes: Vec<Episode>,
    /// One label per faulty fix, in time order.
    pub labels: Vec<Label>,
    /// Fixes read.
    pub fixes: usize,
    /// Median interval between fixes (s).
    pub interval_s: f64,
    /// Lines passed through unread (not faulted), each with its reason.
    pub diagnostics: Diagnostics,
}

/// A parsed fix: where it is in the file and its position.
struct Fix {
    line_idx: usize,
    t_s: f64,
    pos: Geodetic,
}

/// The input's lines and fixes.
struct Input<'a> {
    lines: Vec<&'a [u8]>,
    fixes: Vec<Fix>,
}

/// A step longer than this many nominal intervals is a gap (one missing
/// epoch is not: real RTK logs drop single epochs often, e.g. dataset2).
const GAP_FACTOR: f64 = 2.5;

fn io_err(path: &Path, e: std::io::Error) -> Error {
    Error::Io {
        path: path.to_path_buf(),
        source: e,
    }
}

/// Splits the file into lines and parses its fixes; a line that cannot be
/// read as a fix is reported and passed through; a time out of order is
/// an error (placements need the fixes in time order).
fn parse_input<'a>(
    bytes: &'a [u8],
    path: &Path,
    diag: &mut Diagnostics,
) -> Result<Input<'a>, Error> {
    let mut lines: Vec<&[u8]> = bytes.split(|&b| b == b'\n').collect();
    if lines.last().is_some_and(|l| l.is_empty()) {
        lines.pop();
    }
    let mut fixes: Vec<Fix> = Vec::new();
    let mut last_ns: Option<i64> = None;
    for (idx, &line) in lines.iter().enumerate() {
        let line_no = idx + 1;
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 13] = [b""; 13];
        let nf = split_fields(line, &mut f);
        if nf != 7 && nf != 13 {
            diag.push(
                path,
                line_no,
                format!("expected 7 or 13 fields, found {nf}; copied unchanged, not faulted"),
            );
            continue;
        }
        let ns = match parse_seconds_ns(f[0]) {
            Ok(v) => v,
            Err(e) => {
                diag.push(
                    path,
                    line_no,
                    format!("field 1 (sow): {e}; copied unchanged, not faulted"),
                );
                continue;
            }
        };
        let llh: Result<Vec<f64>, String> = f[1..4].iter().map(|x| parse_f64(x)).collect();
        let llh = match llh {
            Ok(v) if v[0].abs() <= 90.0 && v[1].abs() <= 360.0 && v[2].abs() < 1e5 => v,
            Ok(v) => {
                diag.push(path, line_no, format!("position {v:?} is off the earth (expected lat_deg lon_deg h_m); copied unchanged, not faulted"));
                continue;
            }
            Err(e) => {
                diag.push(
                    path,
                    line_no,
                    format!("position: {e}; copied unchanged, not faulted"),
                );
                continue;
            }
        };
        if let Some(prev) = last_ns
            && ns <= prev
        {
            return Err(Error::Parse {
                path: path.to_path_buf(),
                line: line_no,
                msg: format!(
                    "fix time {} s is not after the previous fix's {} s: fixes must be in time order to place faults (one GPS week per file)",
                    ns as f64 * 1e-9,
                    prev as f64 * 1e-9
                ),
            });
        }
        last_ns = Some(ns);
        fixes.push(Fix {
            line_idx: idx,
            t_s: ns as f64 * 1e-9,
            pos: Geodetic::from_deg(llh[0], llh[1], llh[2]),
        });
    }
    Ok(Input { lines, fixes })
}

/// Median of the steps between fixes (s).
fn median_interval(fixes: &[Fix]) -> f64 {
    let mut d: Vec<f64> = fixes.windows(2).map(|w| w[1].t_s - w[0].t_s).collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// A random offset of norm `size_m`: azimuth uniform, elevation uniform in
/// ±`max_el_deg`; NED (m).
fn draw_direction(r: &mut SimRng, size_m: f64, max_el_deg: f64) -> [f64; 3] {
    let az = rng::uniform_in(r, 0.0, std::f64::consts::TAU);
    let el = rng::uniform_in(r, -max_el_deg, max_el_deg).to_radians();
    [
        size_m * el.cos() * az.cos(),
        size_m * el.cos() * az.sin(),
        -size_m * el.sin(),
    ]
}

/// An episode before placement: class, duration and offset.
struct Draft {
    class: FaultClass,
    duration_s: f64,
    offset: [f64; 3],
}

/// Draws the duration and offset of an episode of `class`.
fn draw_episode(r: &mut SimRng, class: FaultClass, g: &FaultRanges) -> Draft {
    let u = |r: &mut SimRng, x: [f64; 2]| rng::uniform_in(r, x[0], x[1]);
    let (duration_s, size) = match class {
        FaultClass::Spike => (0.0, u(r, g.spike_m)),
        FaultClass::FalseFix => (u(r, g.false_fix_s), u(r, g.false_fix_m)),
        FaultClass::Ramp => (u(r, g.ramp_s), u(r, g.ramp_m)),
        FaultClass::Stale => (u(r, g.stale_s), 0.0),
    };
    let offset = draw_direction(r, size, g.max_elevation_deg);
    Draft {
        class,
        duration_s,
        offset,
    }
}

/// Faulty fixes an episode of this class and duration spans.
fn fixes_for(class: FaultClass, duration_s: f64, interval_s: f64) -> usize {
    match class {
        FaultClass::Spike => 1,
        _ => ((duration_s / interval_s).round() as usize).max(1),
    }
}

/// Why fixes `i..i+n` cannot hold an episode (a previous fix is needed, no
/// step inside or into it may be a gap, no overlap with `taken` widened by
/// `sep_s`), or `None`.
fn placement_problem(
    fixes: &[Fix],
    i: usize,
    n: usize,
    interval_s: f64,
    taken: &[(f64, f64)],
    sep_s: f64,
) -> Option<String> {
    if i == 0 {
        return Some("it would start at the first fix (a fault needs a good fix before it)".into());
    }
    let end = i + n - 1;
    if end >= fixes.len() {
        return Some(format!(
            "it needs {n} fixes from there, the file has {}",
            fixes.len() - i
        ));
    }
    for j in i..=end {
        let step = fixes[j].t_s - fixes[j - 1].t_s;
        if step > GAP_FACTOR * interval_s {
            return Some(format!(
                "it would straddle a {step:.1} s gap before {:.3} s",
                fixes[j].t_s
            ));
        }
    }
    let (a, b) = (fixes[i].t_s, fixes[end].t_s);
    for &(ta, tb) in taken {
        if a <= tb + sep_s && b >= ta - sep_s {
            return Some(format!(
                "it would come within {sep_s} s of the episode at {ta:.3}–{tb:.3} s"
            ));
        }
    }
    None
}

/// An episode placed on fixes `first..first+n`.
struct Placed {
    draft: Draft,
    first: usize,
    n: usize,
}

/// Draws `count` episodes and places them at random on valid fixes.
fn place_drawn(
    input: &Input,
    o: &FaultOptions,
    interval_s: f64,
    path: &Path,
) -> Result<Vec<Placed>, Error> {
    if o.classes.is_empty() {
        return Err(Error::Invalid("no fault classes given".into()));
    }
    let mut params = rng::stream(o.seed, "faults.params");
    let mut place = rng::stream(o.seed, "faults.placement");
    let mut drafts: Vec<Draft> = (0..o.count)
        .map(|k| draw_episode(&mut params, o.classes[k % o.classes.len()], &o.ranges))
        .collect();
    // Longest first: the short ones fit in what is left.
    drafts.sort_by(|a, b| b.duration_s.total_cmp(&a.duration_s));
    let fixes = &input.fixes;
    let t0 = fixes[0].t_s;
    let mut taken: Vec<(f64, f64)> = Vec::new();
    let mut placed = Vec::new();
    for draft in drafts {
        let n = fixes_for(draft.class, draft.duration_s, interval_s);
        let starts: Vec<usize> = (1..fixes.len())
            .filter(|&i| fixes[i].t_s - t0 >= o.skip_start_s)
            .filter(|&i| {
                placement_problem(fixes, i, n, interval_s, &taken, o.min_separation_s).is_none()
            })
            .collect();
        if starts.is_empty() {
            return Err(Error::NoData {
                path: path.to_path_buf(),
                msg: format!(
                    "no room for episode {} of {} ({}, {n} fixes): {} fixes over {:.0} s, none faulted in the first {} s, {} s clean between episodes, none across a gap over {GAP_FACTOR} × the {interval_s:.3} s interval; ask for fewer (--count) or shorter episodes, or start sooner (--skip-start) with less clean time between them (--separation)",
                    placed.len() + 1,
                    o.count,
                    draft.class.name(),
                    fixes.len(),
                    fixes[fixes.len() - 1].t_s - t0,
                    o.skip_start_s,
                    o.min_separation_s
                ),
            });
        }
        let i = starts
            [((rng::uniform(&mut place) * starts.len() as f64) as usize).min(starts.len() - 1)];
        taken.push((fixes[i].t_s, fixes[i + n - 1].t_s));
        placed.push(Placed { draft, first: i, n });
    }
    Ok(placed)
}

/// Places a plan's episodes on the fixes at their times.
fn place_planned(
    input: &Input,
    plan: &Plan,
    o: &FaultOptions,
    interval_s: f64,
    path: &Path,
) -> Result<Vec<Placed>, Error> {
    let mut params = rng::stream(o.seed, "faults.params");
    let fixes = &input.fixes;
    let mut taken: Vec<(f64, f64)> = Vec::new();
    let mut placed = Vec::new();
    for e in &plan.entries {
        let bad = |msg: String| Error::Parse {
            path: plan.path.clone(),
            line: e.line,
            msg,
        };
        let Some(i) = fixes
            .iter()
            .position(|f| (f.t_s - e.start_sow).abs() < 0.5 * interval_s)
        else {
            return Err(bad(format!(
                "no fix at {} s in {}",
                e.start_sow,
                path.display()
            )));
        };
        let mut draft = draw_episode(&mut params, e.class, &o.ranges);
        draft.duration_s = e.duration_s;
        if let Some(off) = e.offset_ned_m {
            draft.offset = off;
        }
        let n = fixes_for(e.class, e.duration_s, interval_s);
        if let Some(why) = placement_problem(fixes, i, n, interval_s, &taken, 0.0) {
            return Err(bad(format!(
                "{} at {} s cannot be placed in {}: {why}",
                e.class.name(),
                e.start_sow,
                path.display()
            )));
        }
        taken.push((fixes[i].t_s, fixes[i + n - 1].t_s));
        placed.push(Placed { draft, first: i, n });
    }
    Ok(placed)
}

/// `pos` moved by `off` (NED, m), exactly through ECEF.
fn moved(pos: &Geodetic, off: &[f64; 3]) -> Geodetic {
    let d = c_ne(pos) * Vector3::new(off[0], off[1], off[2]);
    ecef_to_geodetic(&(geodetic_to_ecef(pos) + d))
}

/// The written line of a fix moved to a new position: its time field and
/// every field after the height unchanged; lat/lon at 1e-11° (~1 µm), h
/// at 0.1 mm (the precision of `io::kfgins::format_gnss_line`). Returns
/// the line and the position as written.
fn moved_line(line: &[u8], to: &Geodetic) -> (Vec<u8>, Geodetic) {
    let mut f: [&[u8]; 13] = [b""; 13];
    let nf = split_fields(line, &mut f).min(13);
    let lat = format!("{:.11}", to.lat_rad.to_degrees());
    let lon = format!("{:.11}", to.lon_rad.to_degrees());
    let h = format!("{:.4}", to.h_m);
    let written = Geodetic::from_deg(
        lat.parse().unwrap_or(f64::NAN),
        lon.parse().unwrap_or(f64::NAN),
        h.parse().unwrap_or(f64::NAN),
    );
    let mut out = f[0].to_vec();
    for s in [lat.as_bytes(), lon.as_bytes(), h.as_bytes()]
        .into_iter()
        .chain(f[4..nf].iter().copied())
    {
        out.push(b' ');
        out.extend_from_slice(s);
    }
    (out, written)
}

/// A stale line: `prev`'s fields after its time, under `line`'s time.
fn stale_line(line: &[u8], prev: &[u8]) -> Vec<u8> {
    let mut f: [&[u8]; 13] = [b""; 13];
    let mut p: [&[u8]; 13] = [b""; 13];
    split_fields(line, &mut f);
    let np = split_fields(prev, &mut p).min(13);
    let mut out = f[0].to_vec();
    for s in &p[1..np] {
        out.push(b' ');
        out.extend_from_slice(s);
    }
    out
}

/// Injects faults into the GNSS file at `path`: the faulty text, the
/// episodes and one label per faulty fix. Errors name the file (and the
/// line): unreadable, no fixes, times out of order, no room for the
/// episodes asked for, a plan entry that does not fit.
pub fn inject(path: &Path, o: &FaultOptions) -> Result<Injection, Error> {
    if let Some(why) = o.ranges.problem() {
        return Err(Error::Invalid(why));
    }
    if !(o.skip_start_s.is_finite()
        && o.skip_start_s >= 0.0
        && o.min_separation_s.is_finite()
        && o.min_separation_s >= 0.0)
    {
        return Err(Error::Invalid(format!(
            "skip-start {} s and separation {} s: expected finite, ≥ 0",
            o.skip_start_s, o.min_separation_s
        )));
    }
    let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
    let mut diagnostics = Diagnostics::default();
    let input = parse_input(&bytes, path, &mut diagnostics)?;
    if input.fixes.len() < 2 {
        return Err(Error::NoData {
            path: path.to_path_buf(),
            msg: format!(
                "{} GNSS fixes read (expected lines `sow lat_deg lon_deg h_m sd_n sd_e sd_d`, 7 or 13 fields); faults need a sequence of fixes",
                input.fixes.len()
            ),
        });
    }
    let interval_s = median_interval(&input.fixes);
    let asked = o.plan.as_ref().map_or(o.count, |p| p.entries.len());
    if asked > input.fixes.len() / 2 {
        return Err(Error::NoData {
            path: path.to_path_buf(),
            msg: format!(
                "{asked} fault episodes asked for, {} fixes read: at most one episode per two fixes",
                input.fixes.len()
            ),
        });
    }
    let mut placed = match &o.plan {
        Some(plan) => place_planned(&input, plan, o, interval_s, path)?,
        None => place_drawn(&input, o, interval_s, path)?,
    };
    placed.sort_by_key(|p| p.first);
    let mut replaced: Vec<Option<Vec<u8>>> = vec![None; input.lines.len()];
    let mut episodes = Vec::with_capacity(placed.len());
    let mut labels = Vec::new();
    for (k, p) in placed.iter().enumerate() {
        let episode = k + 1;
        let mut peak = [0.0f64; 3];
        let prev = &input.fixes[p.first - 1];
        for j in 0..p.n {
            let fix = &input.fixes[p.first + j];
            let line = input.lines[fix.line_idx];
            let (text, written) = match p.draft.class {
                FaultClass::Stale => (stale_line(line, input.lines[prev.line_idx]), prev.pos),
                FaultClass::Ramp => {
                    let s = (j + 1) as f64 / p.n as f64;
                    moved_line(line, &moved(&fix.pos, &p.draft.offset.map(|x| x * s)))
                }
                FaultClass::Spike | FaultClass::FalseFix => {
                    moved_line(line, &moved(&fix.pos, &p.draft.offset))
                }
            };
            let off = ned_offset(&fix.pos, &written);
            let off = [off.x, off.y, off.z];
            if off.iter().map(|x| x * x).sum::<f64>() > peak.iter().map(|x| x * x).sum::<f64>() {
                peak = off;
            }
            let mut fields: [&[u8]; 1] = [b""];
            split_fields(line, &mut fields);
            labels.push(Label {
                sow_text: String::from_utf8_lossy(fields[0]).into_owned(),
                sow: fix.t_s,
                class: p.draft.class,
                episode,
                offset_ned_m: off,
            });
            replaced[fix.line_idx] = Some(text);
        }
        episodes.push(Episode {
            episode,
            class: p.draft.class,
            first_sow: input.fixes[p.first].t_s,
            last_sow: input.fixes[p.first + p.n - 1].t_s,
            fixes: p.n,
            duration_s: p.draft.duration_s,
            offset_ned_m: if p.draft.class == FaultClass::Stale {
                peak
            } else {
                p.draft.offset
            },
        });
    }
    let mut text = Vec::with_capacity(bytes.len() + 64 * labels.len());
    for (idx, line) in input.lines.iter().enumerate() {
        match &replaced[idx] {
            Some(new) => {
                text.extend_from_slice(new);
                if line.ends_with(b"\r") {
                    text.push(b'\r');
                }
            }
            None => text.extend_from_slice(line),
        }
        if idx + 1 < input.lines.len() || bytes.ends_with(b"\n") {
            text.push(b'\n');
        }
    }
    Ok(Injection {
        text,
        episodes,
        labels,
        fixes: input.fixes.len(),
        interval_s,
        diagnostics,
    })
}

/// The labels file: a `#` header citing what each class models, then
/// `sow class episode offset_n_m offset_e_m offset_d_m` per faulty fix.
pub fn labels_text(inj: &Injection, input: &Path, o: &FaultOptions) -> String {
    let mut s = format!(
        "# navsync faults: GNSS faults injected into {} (seed {}); every parameter in faults.json\n\
         # one line per faulty fix: sow class episode offset_n_m offset_e_m offset_d_m\n\
         # offset = written − original antenna position, NED (m), exact through ECEF; fixes not listed are unchanged\n\
         # classes (what each models):\n",
        input.display(),
        o.seed
    );
    for c in FaultClass::ALL {
        s += &format!("#   {}: {}\n", c.name(), c.models(&o.ranges));
    }
    for l in &inj.labels {
        s += &format!(
            "{} {} {} {:.4} {:.4} {:.4}\n",
            l.sow_text,
            l.class.name(),
            l.episode,
            l.offset_ned_m[0],
            l.offset_ned_m[1],
            l.offset_ned_m[2]
        );
    }
    s
}

/// Writes `dir/gnss.txt` (faulty), `dir/faults.txt` (labels) and
/// `dir/faults.json` (options, episodes, diagnostics); each file appears
/// whole or not at all.
pub fn write_outputs(
    dir: &Path,
    input: &Path,
    o: &FaultOptions,
    inj: &Injection,
) -> Result<(), Error> {
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    let mut w = TextWriter::create(&dir.join("gnss.txt"))?;
    w.write(&inj.text)?;
    w.finish()?;
    let mut w = TextWriter::create(&dir.join("faults.txt"))?;
    w.write(labels_text(inj, input, o).as_bytes())?;
    w.finish()?;
    let json = serde_json::json!({
        "input": input.display().to_string(),
        "options": o,
        "fixes": inj.fixes,
        "interval_s": inj.interval_s,
        "faulty_fixes": inj.labels.len(),
        "episodes": inj.episodes,
        "diagnostics": inj.diagnostics,
    });
    let text = serde_json::to_string_pretty(&json)
        .map_err(|e| Error::Invalid(format!("faults.json: {e}")))?;
    let mut w = TextWriter::create(&dir.join("faults.json"))?;
    w.write(text.as_bytes())?;
    w.write(b"\n")?;
    w.finish()
}

/// Reads a plan: one episode a line, `class start_sow duration_s
/// [offset_n_m offset_e_m offset_d_m]` (a ramp's offset is its peak; a
/// stale repeat takes none); `#` comments and blank lines ignored.
pub fn read_plan(path: &Path) -> Result<Plan, Error> {
    let text = std::fs::read(path).map_err(|e| io_err(path, e))?;
    let mut out = Vec::new();
    for (idx, line) in text.split(|&b| b == b'\n').enumerate() {
        if is_blank_or_comment(line) {
            continue;
        }
        let bad = |msg: String| Error::Parse {
            path: path.to_path_buf(),
            line: idx + 1,
            msg: format!(
                "{msg} (expected `class start_sow duration_s [offset_n_m offset_e_m offset_d_m]`)"
            ),
        };
        let mut f: [&[u8]; 6] = [b""; 6];
        let nf = split_fields(line, &mut f);
        if nf != 3 && nf != 6 {
            return Err(bad(format!("{nf} fields")));
        }
        let class = FaultClass::parse(&String::from_utf8_lossy(f[0])).map_err(bad)?;
        let num = |k: usize| parse_f64(f[k]).map_err(|e| bad(format!("field {}: {e}", k + 1)));
        let start_sow = num(1)?;
        let duration_s = num(2)?;
        if !(0.0..=3600.0).contains(&duration_s) {
            return Err(bad(format!("duration {duration_s} s outside [0, 3600]")));
        }
        let offset_ned_m = if nf == 6 {
            if class == FaultClass::Stale {
                return Err(bad(
                    "a stale repeat takes no offset (it repeats the last good fix)".into(),
                ));
            }
            let v = [num(3)?, num(4)?, num(5)?];
            if v.iter().any(|x| x.abs() > 1e4) {
                return Err(bad(format!("offset {v:?} m beyond ±10 km")));
            }
            Some(v)
        } else {
            None
        };
        out.push(PlanEntry {
            class,
            start_sow,
            duration_s,
            offset_ned_m,
            line: idx + 1,
        });
    }
    if out.is_empty() {
        return Err(Error::NoData {
            path: path.to_path_buf(),
            msg: "no episodes (expected lines `class start_sow duration_s [offset_n_m offset_e_m offset_d_m]`)".into(),
        });
    }
    Ok(Plan {
        path: path.to_path_buf(),
        entries: out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync::testfiles::TestDir;

    /// A 1 Hz drive of `n` fixes heading north-east at ~10 m/s, 13 columns
    /// (KF-GINS-Matlab order), with a 20 s gap after fix 150, one missing
    /// epoch before fix 300 and a comment.
    fn drive(n: usize) -> String {
        let mut s = String::from("# sow lat lon h sd… vel…\n");
        let mut t = 200_000.0;
        for k in 0..n {
            t += match k {
                150 => 21.0,
                300 => 2.0,
                _ => 1.0,
            };
            let lat = 30.5 + k as f64 * 6.4e-5;
            let lon = 114.3 + k as f64 * 7.4e-5;
            s += &format!(
                "{t:.6}\t{lat:.10}  {lon:.10} {:.5} 0.010 0.011 0.030 7.1 7.0 0.01 0.02 0.02 0.03\n",
                20.0 + (k as f64 * 0.1).sin()
            );
        }
        s
    }

    fn file(content: &str) -> TestDir {
        let d = TestDir::new("faults").at("gnss.txt");
        std::fs::write(&d, content).unwrap();
        d
    }

    /// (sow, position, every field) of each record line.
    fn records(text: &[u8]) -> Vec<(f64, Geodetic, Vec<String>)> {
        let text = std::str::from_utf8(text).unwrap();
        text.lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .map(|l| {
                let f: Vec<String> = l.split_whitespace().map(str::to_string).collect();
                let v: Vec<f64> = f.iter().map(|x| x.parse().unwrap()).collect();
                (v[0], Geodetic::from_deg(v[1], v[2], v[3]), f)
            })
            .collect()
    }

    fn norm(v: &[f64; 3]) -> f64 {
        v.iter().map(|x| x * x).sum::<f64>().sqrt()
    }

    #[test]
    fn labels_are_the_exact_differences_and_the_rest_is_untouched() {
        let input = drive(400);
        let p = file(&input);
        let o = FaultOptions {
            count: 8,
            ..FaultOptions::default()
        };
        let inj = inject(&p, &o).unwrap();
        assert_eq!(inj.fixes, 400);
        assert_eq!(inj.episodes.len(), 8);
        assert_eq!(
            inj.labels.len(),
            inj.episodes.iter().map(|e| e.fixes).sum::<usize>()
        );
        let (a, b) = (records(input.as_bytes()), records(&inj.text));
        assert_eq!(a.len(), b.len());
        let in_lines: Vec<&str> = input.lines().collect();
        let out_text = String::from_utf8(inj.text.clone()).unwrap();
        let out_lines: Vec<&str> = out_text.lines().collect();
        assert_eq!(in_lines.len(), out_lines.len());
        let mut labelled = 0;
        for (k, (ra, rb)) in a.iter().zip(&b).enumerate() {
            assert_eq!(ra.2[0], rb.2[0], "times are kept");
            match inj.labels.iter().find(|l| l.sow_text == ra.2[0]) {
                None => assert_eq!(
                    in_lines[k + 1],
                    out_lines[k + 1],
                    "unlabelled line {k} byte-identical"
                ),
                Some(l) => {
                    labelled += 1;
                    let d = ned_offset(&ra.1, &rb.1);
                    for i in 0..3 {
                        assert!(
                            (d[i] - l.offset_ned_m[i]).abs() < 1e-6,
                            "{k}: {d:?} vs {:?}",
                            l.offset_ned_m
                        );
                    }
                    assert!(norm(&l.offset_ned_m) > 1e-3 || l.class == FaultClass::Stale);
                    if l.class != FaultClass::Stale {
                        assert_eq!(ra.2[4..], rb.2[4..], "σ and velocity kept on line {k}");
                    }
                }
            }
        }
        assert_eq!(labelled, inj.labels.len());
        // Placements: after the first 60 s, apart, not across the gap.
        let t0 = a[0].0;
        let gap = (a[150].0, a[151].0);
        for (i, e) in inj.episodes.iter().enumerate() {
            assert!(e.first_sow - t0 >= 60.0, "{e:?}");
            assert!(
                !(e.first_sow <= gap.0 && e.last_sow >= gap.1) && e.first_sow != gap.1,
                "{e:?}"
            );
            if i > 0 {
                assert!(e.first_sow - inj.episodes[i - 1].last_sow > 20.0, "{e:?}");
            }
        }
        // The labels file holds the same figures.
        let txt = labels_text(&inj, &p, &o);
        let rows: Vec<&str> = txt.lines().filter(|l| !l.starts_with('#')).collect();
        assert_eq!(rows.len(), inj.labels.len());
        assert!(txt.contains(
            "# one line per faulty fix: sow class episode offset_n_m offset_e_m offset_d_m"
        ));
        for (row, l) in rows.iter().zip(&inj.labels) {
            let f: Vec<&str> = row.split(' ').collect();
            assert_eq!(
                (f[0], f[1], f[2]),
                (l.sow_text.as_str(), l.class.name(), &*l.episode.to_string())
            );
            assert!((f[3].parse::<f64>().unwrap() - l.offset_ned_m[0]).abs() <= 5e-5);
        }
    }

    #[test]
    fn deterministic_per_seed() {
        let p = file(&drive(400));
        let o = FaultOptions::default();
        let x = inject(&p, &o).unwrap();
        let y = inject(&p, &o).unwrap();
        assert_eq!(x.text, y.text);
        assert_eq!(x.labels, y.labels);
        let z = inject(&p, &FaultOptions { seed: 2, ..o }).unwrap();
        assert_ne!(x.labels, z.labels);
    }

    #[test]
    fn each_class_has_its_shape() {
        let input = drive(400);
        let p = file(&input);
        let r = FaultRanges::default();
        let a = records(input.as_bytes());
        for seed in 1..6 {
            let o = FaultOptions {
                seed,
                count: 4,
                ..FaultOptions::default()
            };
            let inj = inject(&p, &o).unwrap();
            let b = records(&inj.text);
            for e in &inj.episodes {
                let ls: Vec<&Label> = inj
                    .labels
                    .iter()
                    .filter(|l| l.episode == e.episode)
                    .collect();
                let sizes: Vec<f64> = ls.iter().map(|l| norm(&l.offset_ned_m)).collect();
                let within = |x: f64, [lo, hi]: [f64; 2]| (lo - 1e-3..=hi + 1e-3).contains(&x);
                match e.class {
                    FaultClass::Spike => {
                        assert_eq!(ls.len(), 1);
                        assert!(within(sizes[0], r.spike_m), "{sizes:?}");
                    }
                    FaultClass::FalseFix => {
                        assert!(within(ls.len() as f64, r.false_fix_s), "{}", ls.len());
                        assert!(within(sizes[0], r.false_fix_m), "{sizes:?}");
                        for l in &ls {
                            for i in 0..3 {
                                // Constant to the 0.1 mm of the written height.
                                assert!(
                                    (l.offset_ned_m[i] - ls[0].offset_ned_m[i]).abs() < 1.1e-4,
                                    "constant"
                                );
                            }
                        }
                    }
                    FaultClass::Ramp => {
                        assert!(within(ls.len() as f64, r.ramp_s), "{}", ls.len());
                        assert!(sizes.windows(2).all(|w| w[1] > w[0]), "monotone {sizes:?}");
                        assert!(within(*sizes.last().unwrap(), r.ramp_m), "{sizes:?}");
                        assert!((sizes.last().unwrap() - norm(&e.offset_ned_m)).abs() < 1e-4);
                    }
                    FaultClass::Stale => {
                        assert!(within(ls.len() as f64, r.stale_s), "{}", ls.len());
                        let k = a.iter().position(|x| x.2[0] == ls[0].sow_text).unwrap();
                        for j in 0..ls.len() {
                            assert_eq!(
                                b[k + j].2[1..],
                                a[k - 1].2[1..],
                                "repeats the last good line"
                            );
                        }
                        // ~10 m/s: a stale repeat falls behind by ~10 m a second.
                        assert!(sizes.windows(2).all(|w| w[1] > w[0] + 5.0), "{sizes:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_plan_is_followed() {
        let input = drive(400);
        let p = file(&input);
        let plan = TestDir::new("faults-plan").at("plan.txt");
        std::fs::write(&plan, "# class start duration [n e d]\nfalse-fix 200080.000000 10 3 -4 0.5\nspike 200300.0 0\nstale 200120 4\nramp 200315 10\n").unwrap();
        let o = FaultOptions {
            plan: Some(read_plan(&plan).unwrap()),
            ..FaultOptions::default()
        };
        let inj = inject(&p, &o).unwrap();
        let cls: Vec<(FaultClass, f64, usize)> = inj
            .episodes
            .iter()
            .map(|e| (e.class, e.first_sow, e.fixes))
            .collect();
        assert_eq!(
            cls,
            [
                (FaultClass::FalseFix, 200080.0, 10),
                (FaultClass::Stale, 200120.0, 4),
                (FaultClass::Spike, 200300.0, 1),
                (FaultClass::Ramp, 200315.0, 10)
            ]
        );
        let l = &inj.labels[0];
        assert!(
            (l.offset_ned_m[0] - 3.0).abs() < 1e-5 && (l.offset_ned_m[1] + 4.0).abs() < 1e-5,
            "{l:?}"
        );
    }

    #[test]
    fn bad_input_is_named() {
        // Too few fixes for the episodes asked for.
        let p = file(&drive(100));
        let e = inject(
            &p,
            &FaultOptions {
                count: 6,
                ..FaultOptions::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("gnss.txt") && e.contains("no room for episode"),
            "{e}"
        );
        let e = inject(
            &p,
            &FaultOptions {
                count: 60,
                ..FaultOptions::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("60 fault episodes asked for, 100 fixes"), "{e}");
        // Out of time order: the line is named.
        let mut lines: Vec<String> = drive(100).lines().map(str::to_string).collect();
        lines.swap(40, 41);
        let p = file(&(lines.join("\n") + "\n"));
        let e = inject(&p, &FaultOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gnss.txt:42:") && e.contains("not after the previous"),
            "{e}"
        );
        // No fixes at all.
        let p = file("# nothing\n1 2 3\n");
        let e = inject(&p, &FaultOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("0 GNSS fixes read"), "{e}");
        // A corrupt line is reported, copied through and never faulted.
        let mut lines: Vec<String> = drive(300).lines().map(str::to_string).collect();
        lines[100] = lines[100].replacen("0.010", "x", 1);
        let text = lines.join("\n") + "\n";
        let p = file(&text);
        let inj = inject(&p, &FaultOptions::default()).unwrap();
        assert_eq!(inj.diagnostics.total, 0, "σ fields are not read");
        lines[120] = "200121.0 30.5 nope 20 0.01 0.01 0.03".into();
        let p = file(&(lines.join("\n") + "\n"));
        let inj = inject(&p, &FaultOptions::default()).unwrap();
        assert_eq!(inj.diagnostics.total, 1);
        assert!(
            inj.diagnostics.items[0].to_string().contains(":121:"),
            "{:?}",
            inj.diagnostics.items
        );
        assert!(
            String::from_utf8(inj.text)
                .unwrap()
                .contains("200121.0 30.5 nope 20")
        );
        // Ranges and plans.
        let bad = FaultRanges {
            ramp_m: [3.0, 1.0],
            ..FaultRanges::default()
        };
        let e = inject(
            &p,
            &FaultOptions {
                ranges: bad,
                ..FaultOptions::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("ramp peak (m) range [3, 1]"), "{e}");
        let plan = TestDir::new("faults-plan").at("plan.txt");
        for (text, want) in [
            (
                "stale 200100 3 1 2 3\n",
                "plan.txt:1: a stale repeat takes no offset",
            ),
            ("ramp 200100\n", "plan.txt:1: 2 fields"),
            ("wobble 200100 3\n", "unknown fault class 'wobble'"),
            ("\nspike 200100.5 0\n", "plan.txt:2: no fix at 200100.5 s"),
            (
                "ramp 200140 20\n",
                "plan.txt:1: ramp at 200140 s cannot be placed",
            ),
            (
                "ramp 200080 20\nspike 200090 0\n",
                "plan.txt:2: spike at 200090 s cannot be placed",
            ),
        ] {
            std::fs::write(&plan, text).unwrap();
            let e = read_plan(&plan).and_then(|pl| {
                inject(
                    &p,
                    &FaultOptions {
                        plan: Some(pl),
                        ..FaultOptions::default()
                    },
                )
            });
            let e = e.unwrap_err().to_string();
            assert!(e.contains(want), "{text}: {e}");
        }
    }
}
