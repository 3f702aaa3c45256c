//! The sections that judge a run from the filter's own statistics (no
//! reference needed): the verdict, GNSS innovations and NIS, the filter's
//! σ, the IMU biases against the configured datasheet figures, data gaps
//! and the predicted drift through them.

use std::fmt::Write as _;

use navsync::Error;
use navsync::timing::SyncReport;
use serde_json::Value;

use crate::html::{MAX_POINTS, Rows, WIDTH, escape, row, section};
use crate::inputs::{FixWeight, rel_s};
use crate::plot::{self, AXES, BLUE, Band, Figure, GREY, Line, ORANGE, PURPLE, Panel, RED, Shade};
use crate::quality::{
    self, AlignEvidence, BIAS_SIGMAS, BiasCheck, DRIFT_MIN_GAP_S, Evidence, FixEvidence,
    GAP_FACTOR, Grade, NIS_CONF, POSITION_DOF, SyncEvidence, Verdict,
};

const X_LABEL: &str = "time since the first epoch (s)";

/// One GNSS gap or scheduled outage (times relative to the first epoch).
#[derive(Clone, Debug)]
pub(crate) struct Gap {
    pub start: f64,
    pub end: f64,
    pub start_sow: f64,
    /// "gap in the fixes" or "scheduled outage".
    pub kind: &'static str,
    /// Predicted horizontal σ at the start and its peak inside (m).
    pub drift: Option<(f64, f64)>,
    /// The first fix after it against the prediction, when tested.
    pub end_test: Option<crate::gap_ends::GapEnd>,
}

/// The filter's horizontal σ over time, (t, √(σ_n² + σ_e²)) from std.txt.
pub(crate) fn horizontal_sigma(std: &[Vec<f64>], t0: f64) -> Vec<(f64, f64)> {
    std.iter()
        .map(|r| (rel_s(r[0], t0), r[1].hypot(r[2])))
        .collect()
}

/// GNSS gaps in `fix_times` (relative, sorted) and the scheduled outages
/// not already among them, with the predicted drift through those of at
/// least [`DRIFT_MIN_GAP_S`].
pub(crate) fn gaps(
    fix_times: &[f64],
    outages: &[(f64, f64)],
    sigma_h: &[(f64, f64)],
    t0: f64,
) -> Vec<Gap> {
    let mut out: Vec<Gap> = quality::find_gaps(fix_times)
        .into_iter()
        .map(|(a, b)| Gap {
            start: a,
            end: b,
            start_sow: t0 + a,
            kind: "gap in the fixes",
            drift: None,
            end_test: None,
        })
        .collect();
    for &(a, b) in outages {
        if !out.iter().any(|g| g.start < b && a < g.end) {
            out.push(Gap {
                start: a,
                end: b,
                start_sow: t0 + a,
                kind: "scheduled outage",
                drift: None,
                end_test: None,
            });
        }
    }
    out.sort_by(|x, y| x.start.total_cmp(&y.start));
    for g in &mut out {
        if g.end - g.start >= DRIFT_MIN_GAP_S {
            g.drift = quality::drift_through(sigma_h, g.start, g.end);
        }
    }
    out
}

/// Tests the end of every gap of at least [`DRIFT_MIN_GAP_S`]: the first
/// fix after it against the forward filter's σ (`std`, its std.txt rows)
/// and the fix after that ([`crate::gap_ends`]).
pub(crate) fn test_gap_ends(gaps: &mut [Gap], fixes: &[FixWeight], std: &[Vec<f64>], t0: f64) {
    let long: Vec<usize> = (0..gaps.len())
        .filter(|&i| gaps[i].end - gaps[i].start >= DRIFT_MIN_GAP_S)
        .collect();
    let spans: Vec<crate::gap_ends::GapSpan> = long
        .iter()
        .map(|&i| crate::gap_ends::GapSpan {
            gap_s: gaps[i].end - gaps[i].start,
            end_sow: (t0 + gaps[i].end).rem_euclid(604_800.0),
            start_sd_h_m: gaps[i].drift.map_or(f64::NAN, |(start, _)| start),
        })
        .collect();
    for (i, end) in long
        .into_iter()
        .zip(crate::gap_ends::measure_all(&spans, fixes, std))
    {
        gaps[i].end_test = end;
    }
}

/// The fixes' share of the evidence.
pub(crate) fn fix_evidence(fixes: &[FixWeight]) -> FixEvidence {
    let mut h_sd: Vec<f64> = fixes.iter().map(|f| f.sd[0].hypot(f.sd[1])).collect();
    h_sd.sort_by(f64::total_cmp);
    FixEvidence {
        fixes: fixes.len(),
        rejected: fixes.iter().filter(|f| f.status == "rejected").count(),
        down_weighted: fixes.iter().filter(|f| f.status == "down-weighted").count(),
        nis: fixes
            .iter()
            .filter(|f| f.status != "rejected" && f.nis.is_finite())
            .map(|f| f.nis)
            .collect(),
        median_fix_h_sd_m: h_sd.get(h_sd.len() / 2).copied().unwrap_or(0.0),
        faults: fault_evidence(fixes),
    }
}

/// One fault episode of the integrity monitor, read back from the
/// fixes' reasons in gnss_residuals.txt (the file that was written).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct FaultSpan {
    /// GPS seconds of week of its first and last excluded fix.
    pub start_sow: f64,
    pub end_sow: f64,
    /// Fixes excluded in it.
    pub excluded: usize,
    /// `stale` (repeated outputs), `jump` (the fixes moved) or `smoother`
    /// (excluded by the smoother's re-judgement).
    pub kind: &'static str,
    /// Fixes used again after it without the INS resolving it
    /// (`persisted`): the solution there follows fixes that may be faulty.
    pub persisted: usize,
}

/// The integrity monitor's episodes, from the fixes' reasons: a `jump`
/// opens one and the `run`/`ramp` fixes after it belong to it, a run of
/// `stale` or of `smoother-excluded` fixes is one, and `persisted` fixes
/// are counted against the episode they follow.
pub(crate) fn fault_spans(fixes: &[FixWeight]) -> Vec<FaultSpan> {
    let mut out: Vec<FaultSpan> = Vec::new();
    // Whether the last fix extended the open episode of that kind.
    let mut open: Option<&'static str> = None;
    for f in fixes {
        let kind = match f.reason.as_str() {
            // A jump or a ramp's onset opens an episode.
            "jump" | "ramp" => {
                open = None;
                Some("jump")
            }
            "run" => Some("jump"),
            "stale" => Some("stale"),
            // Fixes the smoother's re-judgement excluded (a ramp the
            // forward pass followed, a level it accepted): one episode
            // per run of them.
            "smoother-excluded" => Some("smoother"),
            "persisted" => {
                if let Some(last) = out.last_mut() {
                    last.persisted += 1;
                }
                open = None;
                None
            }
            _ => {
                open = None;
                None
            }
        };
        let Some(kind) = kind else { continue };
        match out.last_mut() {
            Some(last) if open == Some(kind) => {
                last.end_sow = f.sow;
                last.excluded += 1;
            }
            _ => out.push(FaultSpan {
                start_sow: f.sow,
                end_sow: f.sow,
                excluded: 1,
                kind,
                persisted: 0,
            }),
        }
        open = Some(kind);
    }
    out
}

fn fault_evidence(fixes: &[FixWeight]) -> quality::FaultEvidence {
    let spans = fault_spans(fixes);
    quality::FaultEvidence {
        episodes: spans.len(),
        excluded: spans.iter().map(|s| s.excluded).sum(),
        persisted: spans.iter().map(|s| s.persisted).sum(),
    }
}

/// The fault episodes as shaded spans (times relative to `t0`), those
/// the INS resolved and those followed again unresolved; a one-fix
/// episode gets a visible width of 0.3 % of the run.
pub(crate) fn fault_shades(spans: &[FaultSpan], t0: f64, run_s: f64) -> [Shade; 2] {
    let min_w = 0.003 * run_s.max(1e-9);
    let pick = |unresolved: bool| -> Vec<(f64, f64)> {
        spans
            .iter()
            .filter(|s| (s.persisted > 0) == unresolved)
            .map(|s| {
                let a = rel_s(s.start_sow, t0);
                (a, rel_s(s.end_sow, t0).max(a + min_w))
            })
            .collect()
    };
    [
        Shade {
            name: "GNSS fault episode".into(),
            color: RED,
            spans: pick(false),
        },
        Shade {
            name: "fault, unresolved".into(),
            color: PURPLE,
            spans: pick(true),
        },
    ]
}

/// The table of fault episodes under the GNSS weighting section.
pub(crate) fn fault_table(html: &mut String, spans: &[FaultSpan], t0: f64) {
    if spans.is_empty() {
        return;
    }
    let unresolved = spans.iter().filter(|s| s.persisted > 0).count();
    let _ = writeln!(
        html,
        "<details><summary>GNSS fault episodes: {} ({} excluded fixes; {unresolved} followed again without the INS resolving them)</summary>\n<table class=\"metrics\"><tr><th>start (s)</th><th>length (s)</th><th>kind</th><th>fixes excluded</th><th>fixes then used again unresolved</th></tr>",
        spans.len(),
        spans.iter().map(|s| s.excluded).sum::<usize>()
    );
    for s in spans.iter().take(200) {
        let _ = writeln!(
            html,
            "<tr><td>{:.1}</td><td>{:.1}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            rel_s(s.start_sow, t0),
            s.end_sow - s.start_sow,
            s.kind,
            s.excluded,
            s.persisted
        );
    }
    html.push_str("</table></details>\n");
}

fn triplet(v: Option<&Value>) -> Option<[f64; 3]> {
    let a = v?.as_array()?;
    if a.len() != 3 {
        return None;
    }
    Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?])
}

/// Each bias axis of `imu_err.txt` against summary.json's `imu_model`:
/// the configured initial bias ± σ(t) relaxing from the configured initial
/// σ to the bias instability ([`quality::bias_prior_sd`]). Empty when
/// either is missing (summaries written before `imu_model` existed).
///
/// An accelerometer axis also carries gravity through the axes'
/// misalignment and its own scale factor; the filter has no misalignment
/// state and cannot tell a scale factor from a bias along a steady gravity,
/// so both widen that axis's envelope ([`quality::gravity_coupling_sd`]),
/// from gravity's direction in the IMU's axes at the run's median
/// `roll_pitch_rad` (level when unknown). For the same reason an
/// accelerometer axis is judged by what the data observe, its bias plus
/// its estimated scale factor times gravity's specific force on it
/// (b̂ + ŝ·f, f = −g·u: the sensor model m = (1 + s)·f + b, Groves 2013
/// §4.4.5): where the filter estimates both, their split along that ridge
/// is arbitrary (a clean simulated ICM-20602 drive put its z bias at
/// +38 080 mGal and its scale at +39 618 ppm, the sum −772 mGal; the bias
/// alone read 6.9σ outside the envelope).
pub(crate) fn bias_checks(
    summary: Option<&Value>,
    imu_err: Option<&[Vec<f64>]>,
    roll_pitch_rad: Option<[f64; 2]>,
) -> Vec<BiasCheck> {
    let (Some(model), Some(rows)) = (summary.and_then(|s| s.get("imu_model")), imu_err) else {
        return Vec::new();
    };
    let Some(t_first) = rows.first().map(|r| r[0]) else {
        return Vec::new();
    };
    let tau = model
        .get("corr_time_s")
        .and_then(Value::as_f64)
        .unwrap_or(0.0);
    let mut out = Vec::new();
    for (g, (what, unit, key)) in [
        ("gyro", "deg/h", "gyro_bias"),
        ("accel", "mGal", "accel_bias"),
    ]
    .into_iter()
    .enumerate()
    {
        let get = |name: String| triplet(model.get(&name));
        let (Some(instab), Some(init_sd), Some(center)) = (
            get(format!("{key}_sd_{}", unit_key(unit))),
            get(format!("init_{key}_sd_{}", unit_key(unit))),
            get(format!("init_{key}_{}", unit_key(unit))),
        ) else {
            continue;
        };
        let misalign_sd_rad = summary
            .and_then(|s| s.pointer("/options/accel_misalignment_sd_deg"))
            .and_then(Value::as_f64)
            .unwrap_or(0.0)
            .to_radians();
        let scale_sd_ppm = triplet(model.get("accel_scale_sd_ppm")).unwrap_or([0.0, 0.0, 0.0]);
        let [roll, pitch] = roll_pitch_rad.unwrap_or([0.0, 0.0]);
        // Gravity's direction in the IMU's axes (Groves 2013, eq. 5.56 at rest).
        let down_b = [
            -pitch.sin(),
            roll.sin() * pitch.cos(),
            roll.cos() * pitch.cos(),
        ];
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let cross_sd = if what == "accel" {
                quality::gravity_coupling_sd(down_b, a, misalign_sd_rad, scale_sd_ppm[a])
            } else {
                0.0
            };
            let sd_at = |sow: f64| {
                quality::bias_prior_sd(init_sd[a], instab[a], tau, rel_s(sow, t_first))
                    .hypot(cross_sd)
            };
            let col = 1 + 3 * g + a;
            // b̂ + ŝ·f on an accelerometer axis (its scale column, ppm,
            // when imu_err.txt has one).
            let scale_force_mgal = if what == "accel" {
                -quality::G_MGAL * down_b[a]
            } else {
                0.0
            };
            let estimate = |r: &[f64]| judged_bias(r, col, 10 + a, scale_force_mgal);
            let max_sigmas = rows
                .iter()
                .map(|r| (estimate(r) - center[a]).abs() / sd_at(r[0]))
                .fold(0.0, f64::max);
            let Some(last) = rows.last() else { continue };
            let final_sd = sd_at(last[0]);
            if final_sd.is_nan() || final_sd <= 0.0 {
                continue;
            }
            out.push(BiasCheck {
                axis: format!("{what} {axis}"),
                unit,
                center: center[a],
                init_sd: init_sd[a],
                instability_sd: instab[a],
                corr_time_s: tau,
                final_estimate: estimate(last),
                final_sd,
                max_sigmas,
                cross_sd,
                scale_force_mgal,
            });
        }
    }
    out
}

/// The bias estimate judged against the envelope, from an imu_err.txt
/// row: the bias column plus the scale column (ppm) times the specific
/// force `scale_force_mgal` (0 for a gyro; [`bias_checks`]).
fn judged_bias(row: &[f64], bias_col: usize, scale_col: usize, scale_force_mgal: f64) -> f64 {
    let scale_ppm = row.get(scale_col).copied().unwrap_or(0.0);
    row[bias_col] + scale_ppm * 1e-6 * scale_force_mgal
}

/// The suffix of summary.json's `imu_model` keys for a unit.
fn unit_key(unit: &str) -> &'static str {
    if unit == "deg/h" { "deg_h" } else { "mgal" }
}

/// The synchronization facts the verdict weighs.
pub(crate) fn sync_evidence(
    sync: Option<&SyncReport>,
    summary: Option<&Value>,
) -> Option<SyncEvidence> {
    let max_imu_gap_s = summary
        .and_then(|s| s.get("stats"))
        .and_then(|st| st.get("max_gap_s"))
        .and_then(Value::as_f64);
    if sync.is_none() && max_imu_gap_s.is_none() {
        return None;
    }
    Some(SyncEvidence {
        imu_loss_fraction: sync.map(|s| {
            let lost = s.imu.lost as f64;
            lost / (s.records.imu as f64 + lost).max(1.0)
        }),
        max_stamp_bound_us: sync.and_then(|s| s.stamp_bound_us.max),
        max_imu_gap_s,
    })
}

/// summary.json's `alignment` object, when `fuse --align` ran.
pub(crate) fn align_evidence(summary: Option<&Value>) -> Option<AlignEvidence> {
    let a = summary?.get("alignment")?;
    if a.is_null() {
        return None;
    }
    let mut ev = AlignEvidence {
        method: a.get("method")?.as_str()?.to_string(),
        time_sow: a.get("time_sow")?.as_f64()?,
        yaw_sd_deg: triplet(a.get("att_sd_rad"))?[2].to_degrees(),
        note: a
            .get("note")
            .and_then(Value::as_str)
            .unwrap_or_default()
            .to_string(),
    };
    // A heading found later from the GNSS track (fusion::course_heading).
    if let Some(h) = summary?.get("heading_acquired").filter(|h| !h.is_null())
        && let (Some(sow), Some(sd)) = (
            h.get("time_sow").and_then(Value::as_f64),
            h.get("sd_rad").and_then(Value::as_f64),
        )
    {
        ev.method = "course-from-track".into();
        ev.note = format!(
            "{}; the heading was found from the GNSS track at SOW {sow:.1} (σ {:.1}°) and the epochs before turned by it in the smoothed output",
            ev.note,
            sd.to_degrees()
        );
        ev.yaw_sd_deg = sd.to_degrees();
    }
    Some(ev)
}

/// The worst predicted drift among the gaps: (length s, σ at its end m).
pub(crate) fn worst_gap(gaps: &[Gap]) -> Option<(f64, f64)> {
    gaps.iter()
        .filter_map(|g| g.drift.map(|(_, peak)| (g.end - g.start, peak)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

fn grade_cell(g: Option<Grade>) -> String {
    match g {
        Some(g) => format!(
            "<span class=\"grade {}\">{}</span>",
            match g {
                Grade::Good => "good",
                Grade::Caution => "caution",
                Grade::Poor => "poor",
            },
            g.words()
        ),
        None => "information".into(),
    }
}

/// The verdict at the top of the page.
pub(crate) fn verdict_section(html: &mut String, v: &Verdict, with_truth: bool) {
    let _ = writeln!(
        html,
        "<section id=\"verdict\"><h2>Verdict: {}</h2>",
        grade_cell(Some(v.grade))
    );
    let reasons: Vec<String> = v
        .checks
        .iter()
        .filter(|c| c.grade.is_some_and(|g| g > Grade::Good))
        .map(|c| format!("{}: {}", escape(c.name), escape(&c.finding)))
        .collect();
    if reasons.is_empty() {
        html.push_str("<p>Every graded check passed.</p>\n");
    } else {
        let _ = writeln!(html, "<p>Because of: {}.</p>", reasons.join("; "));
    }
    if !v.causes.is_empty() {
        html.push_str("<p>Likely causes:</p>\n<ul>\n");
        for c in &v.causes {
            let _ = writeln!(html, "<li>{}</li>", escape(c));
        }
        html.push_str("</ul>\n");
    }
    let _ = writeln!(
        html,
        "<p class=\"note\">The verdict is the worst grade of the checks below, made from the filter's own statistics{}; each rule and why it has its value is in docs/report.md. Absent files are not assessed.</p>",
        if with_truth {
            " (the truth comparison further down is not part of it)"
        } else {
            ", without a reference trajectory"
        }
    );
    html.push_str("<table class=\"metrics kv\"><tr><th>check</th><th>grade</th><th>finding</th><th>rule</th></tr>\n");
    for c in &v.checks {
        row(
            html,
            &[
                escape(c.name),
                grade_cell(c.grade),
                escape(&c.finding),
                escape(&c.rule),
            ],
        );
    }
    html.push_str("</table></section>\n");
}

/// σ of one std.txt component at `t` (the last row at or before it).
fn sigma_at(std: &[(f64, [f64; 3])], t: f64) -> Option<[f64; 3]> {
    let k = std.partition_point(|r| r.0 <= t);
    (k > 0).then(|| std[k - 1].1)
}

fn stride_pts(pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    let k = plot::stride(pts.len(), MAX_POINTS);
    pts.into_iter().step_by(k).collect()
}

/// GNSS innovations N/E/D with ±3σ of the innovation, the rejected and
/// down-weighted fixes marked.
pub(crate) fn innovation_section(
    html: &mut String,
    fixes: &[FixWeight],
    std: Option<&[Vec<f64>]>,
    t0: f64,
    x1: f64,
    shades: &[Shade],
) -> Result<(), Error> {
    let pos_sd: Vec<(f64, [f64; 3])> = std
        .unwrap_or_default()
        .iter()
        .map(|r| (rel_s(r[0], t0), [r[1], r[2], r[3]]))
        .collect();
    let panels = (0..3)
        .map(|c| {
            let of = |status: &str| {
                stride_pts(
                    fixes
                        .iter()
                        .filter(|f| f.status == status)
                        .map(|f| (rel_s(f.sow, t0), f.innovation[c]))
                        .collect(),
                )
            };
            // S_ii ≈ σ_fix² + σ_filter² (H = I for a position fix; the lever
            // arm's attitude term is left out).
            let band: Vec<(f64, f64, f64)> = stride_pts(
                fixes
                    .iter()
                    .map(|f| {
                        let t = rel_s(f.sow, t0);
                        let p = sigma_at(&pos_sd, t).map_or(0.0, |s| s[c]);
                        (t, 3.0 * f.sd[c].hypot(p))
                    })
                    .collect(),
            )
            .into_iter()
            .map(|(t, s)| (t, -s, s))
            .collect();
            let mut used = of("used");
            used.extend(of("drift-accepted"));
            used.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut mags: Vec<f64> = used
                .iter()
                .map(|p| p.1.abs())
                .chain(band.iter().map(|b| b.2))
                .collect();
            mags.sort_by(f64::total_cmp);
            let top = mags
                .get((mags.len() as f64 * 0.995) as usize)
                .or(mags.last())
                .copied()
                .unwrap_or(1.0)
                .max(1e-3)
                * 1.1;
            Panel {
                title: format!("GNSS position innovation, {}", ["north", "east", "down"][c]),
                y_label: "predicted − measured (m)".into(),
                lines: Vec::new(),
                bands: vec![Band {
                    name: if std.is_some() {
                        "±3√(σ_fix² + σ_filter²)"
                    } else {
                        "±3σ_fix (no std.txt)"
                    }
                    .into(),
                    color: GREY,
                    pts: band,
                }],
                dots: vec![
                    Line {
                        name: "used".into(),
                        color: AXES[c],
                        width: 1,
                        pts: used,
                    },
                    Line {
                        name: "down-weighted".into(),
                        color: ORANGE,
                        width: 3,
                        pts: of("down-weighted"),
                    },
                    Line {
                        name: "rejected".into(),
                        color: RED,
                        width: 3,
                        pts: of("rejected"),
                    },
                ],
                y_range: Some((-top, top)),
            }
        })
        .collect();
    let svg = plot::time_series(&Figure {
        x_label: X_LABEL.into(),
        x_range: (0.0, x1),
        shades: shades.to_vec(),
        panels,
        width: WIDTH,
        panel_height: 210,
    })?;
    section(
        html,
        "innovations",
        "GNSS innovations",
        "Innovation = the filter's predicted position − the fix (gnss_residuals.txt). The band is ±3 × the innovation's σ, taken as √(σ_fix² + σ_filter²) with σ_filter from std.txt: about 99.7 % of the dots should fall inside when both σ are right. Fixes beyond the plot's range are drawn at its edge.",
        &svg,
    );
    Ok(())
}

/// NIS of every position fix, its single-fix 95 % interval, and its
/// running mean against the interval of a mean over the window.
pub(crate) fn nis_section(
    html: &mut String,
    fixes: &[FixWeight],
    t0: f64,
    x1: f64,
    shades: &[Shade],
) -> Result<(), Error> {
    let Some((lo1, hi1)) = quality::nis_mean_interval(1, POSITION_DOF, NIS_CONF) else {
        return Ok(());
    };
    let lg = |x: f64| x.max(1e-6).log10();
    let kept: Vec<&FixWeight> = fixes
        .iter()
        .filter(|f| f.status != "rejected" && f.nis.is_finite())
        .collect();
    // Window of the running mean: 1/20 of the fixes, 10 … 100.
    let w = (kept.len() / 20).clamp(10, 100).min(kept.len().max(1));
    let mut mean_pts = Vec::new();
    let mut sum = 0.0;
    for (i, f) in kept.iter().enumerate() {
        sum += f.nis;
        if i >= w {
            sum -= kept[i - w].nis;
        }
        if i + 1 >= w {
            mean_pts.push((rel_s(f.sow, t0), lg(sum / w as f64)));
        }
    }
    let (lo_w, hi_w) = quality::nis_mean_interval(w, POSITION_DOF, NIS_CONF).unwrap_or((lo1, hi1));
    let dots = |status: &str| -> Vec<(f64, f64)> {
        stride_pts(
            fixes
                .iter()
                .filter(|f| f.status == status)
                .map(|f| (rel_s(f.sow, t0), lg(f.nis)))
                .collect(),
        )
    };
    let hline = |v: f64| vec![(0.0, lg(v)), (x1, lg(v))];
    let inside = kept.iter().filter(|f| f.nis >= lo1 && f.nis <= hi1).count();
    let mean = kept.iter().map(|f| f.nis).sum::<f64>() / kept.len().max(1) as f64;
    let (lo_n, hi_n) =
        quality::nis_mean_interval(kept.len(), POSITION_DOF, NIS_CONF).unwrap_or((lo1, hi1));
    let mut used = dots("used");
    used.extend(dots("drift-accepted"));
    used.sort_by(|a, b| a.0.total_cmp(&b.0));
    let svg = plot::time_series(&Figure {
        x_label: X_LABEL.into(),
        x_range: (0.0, x1),
        shades: shades.to_vec(),
        panels: vec![Panel {
            title: "GNSS position NIS at the stated σ, log10 (3 degrees of freedom)".into(),
            y_label: "log10 NIS".into(),
            lines: vec![
                Line {
                    name: "single-fix 95 % interval".into(),
                    color: GREY,
                    width: 2,
                    pts: hline(lo1),
                },
                Line {
                    name: String::new(),
                    color: GREY,
                    width: 2,
                    pts: hline(hi1),
                },
                Line {
                    name: format!("mean of {w} fixes"),
                    color: PURPLE,
                    width: 2,
                    pts: mean_pts,
                },
                Line {
                    name: format!("95 % of a {w}-fix mean"),
                    color: BLUE,
                    width: 1,
                    pts: hline(lo_w),
                },
                Line {
                    name: String::new(),
                    color: BLUE,
                    width: 1,
                    pts: hline(hi_w),
                },
            ],
            bands: Vec::new(),
            dots: vec![
                Line {
                    name: "NIS (used)".into(),
                    color: GREY,
                    width: 1,
                    pts: used,
                },
                Line {
                    name: "down-weighted".into(),
                    color: ORANGE,
                    width: 3,
                    pts: dots("down-weighted"),
                },
                Line {
                    name: "rejected".into(),
                    color: RED,
                    width: 3,
                    pts: dots("rejected"),
                },
            ],
            y_range: Some((-3.0, 4.0)),
        }],
        width: WIDTH,
        panel_height: 320,
    })?;
    let note = format!(
        "NIS = νᵀS⁻¹ν with the stated fix σ (gnss_residuals.txt): χ²(3) when the filter is consistent. {} of {} fixes not rejected ({:.1} %) inside the single-fix 95 % interval [{lo1:.3}, {hi1:.3}] (95 % expected); mean {mean:.2} against the 95 % interval of a mean over {} fixes [{lo_n:.3}, {hi_n:.3}] (χ²(3n)/n, Bar-Shalom, Li & Kirubarajan 2001, §5.4.2). Consecutive fixes are correlated, so the intervals of means are narrower than they should be. Values beyond 10⁴ or below 10⁻³ are drawn at the edge.",
        inside,
        kept.len(),
        100.0 * inside as f64 / kept.len().max(1) as f64,
        kept.len()
    );
    section(html, "nis", "GNSS NIS (filter consistency)", &note, &svg);
    Ok(())
}

/// The filter's σ over time from std.txt.
pub(crate) fn sigma_section(
    html: &mut String,
    std: &Rows,
    x1: f64,
    shades: &[Shade],
    smoothed: bool,
) -> Result<(), Error> {
    let groups = [
        ("position", "m", 1, ["north", "east", "down"]),
        ("velocity", "m/s", 4, ["north", "east", "down"]),
        ("attitude", "deg", 7, ["roll", "pitch", "yaw"]),
        ("gyro bias", "deg/h", 10, ["x", "y", "z"]),
        ("accelerometer bias", "mGal", 13, ["x", "y", "z"]),
    ];
    // The y scale leaves out the first 5 % of the run, where the initial σ
    // would flatten everything else.
    let settle = 0.05 * x1;
    let panels = groups
        .iter()
        .map(|(name, unit, c0, comps)| {
            let top = std
                .t
                .iter()
                .zip(&std.rows)
                .filter(|(t, _)| **t >= settle)
                .flat_map(|(_, r)| (0..3).map(move |k| r[c0 + k]))
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max);
            Panel {
                title: format!("{name} σ"),
                y_label: format!("σ ({unit})"),
                lines: (0..3)
                    .map(|k| Line {
                        name: comps[k].to_string(),
                        color: AXES[k],
                        width: 2,
                        pts: std.col(c0 + k, 1.0),
                    })
                    .collect(),
                bands: Vec::new(),
                dots: Vec::new(),
                y_range: (top > 0.0).then_some((0.0, 1.15 * top)),
            }
        })
        .collect();
    let svg = plot::time_series(&Figure {
        x_label: X_LABEL.into(),
        x_range: (0.0, x1),
        shades: shades.to_vec(),
        panels,
        width: WIDTH,
        panel_height: 190,
    })?;
    section(
        html,
        "filter-sigma",
        if smoothed {
            "The smoother's σ"
        } else {
            "The filter's σ"
        },
        "Standard deviations from std.txt (attitude: the φ-angle σ). The y scale leaves out the first 5 % of the run; larger values are drawn at the top edge. Shaded: GNSS gaps and outages.",
        &svg,
    );
    Ok(())
}

/// The bias estimates with the configured ±σ and ±3σ, and a table.
pub(crate) fn imu_envelope_section(
    html: &mut String,
    checks: &[BiasCheck],
    imu_err: &Rows,
    x1: f64,
    shades: &[Shade],
) -> Result<(), Error> {
    let panels = checks
        .iter()
        .map(|b| {
            let g = usize::from(!b.axis.starts_with("gyro"));
            let axis = ["x", "y", "z"]
                .iter()
                .position(|x| b.axis.ends_with(x))
                .unwrap_or(0);
            let env = |k: f64| -> Vec<(f64, f64, f64)> {
                imu_err
                    .t
                    .iter()
                    .map(|&t| {
                        let t_run = t - imu_err.t.first().copied().unwrap_or(0.0);
                        let sd = quality::bias_prior_sd(
                            b.init_sd,
                            b.instability_sd,
                            b.corr_time_s,
                            t_run,
                        )
                        .hypot(b.cross_sd);
                        (t, b.center - k * sd, b.center + k * sd)
                    })
                    .collect()
            };
            Panel {
                title: format!("{} bias", b.axis),
                y_label: format!("({})", b.unit),
                lines: vec![Line {
                    name: if b.scale_force_mgal != 0.0 {
                        "estimate (bias + scale × gravity)".into()
                    } else {
                        "estimate".into()
                    },
                    color: AXES[axis],
                    width: 2,
                    pts: imu_err
                        .t
                        .iter()
                        .zip(&imu_err.rows)
                        .map(|(&t, r)| {
                            (
                                t,
                                judged_bias(r, 1 + 3 * g + axis, 10 + axis, b.scale_force_mgal),
                            )
                        })
                        .collect(),
                }],
                bands: vec![
                    Band {
                        name: "configured ±3σ".into(),
                        color: GREY,
                        pts: env(BIAS_SIGMAS),
                    },
                    Band {
                        name: "configured ±σ".into(),
                        color: BLUE,
                        pts: env(1.0),
                    },
                ],
                dots: Vec::new(),
                y_range: None,
            }
        })
        .collect();
    let svg = plot::time_series(&Figure {
        x_label: X_LABEL.into(),
        x_range: (0.0, x1),
        shades: shades.to_vec(),
        panels,
        width: WIDTH,
        panel_height: 170,
    })?;
    section(
        html,
        "imu-envelope",
        "IMU biases against the datasheet",
        "Estimates (imu_err.txt) against the configured spread of each bias about the configured initial bias (initgyrbias, initaccbias): σ(t)² = σ₀² e^(−2t/τ) + σ_GM² (1 − e^(−2t/τ)), from the initial σ (initbgstd, initbastd) toward the bias instability (imunoise gbstd, abstd) with the correlation time τ (corrtime), the first-order Gauss–Markov model the filter uses, as summary.json's imu_model records them; an accelerometer's envelope adds gravity through the axes' misalignment and its scale factor, g √(σ_m² (1 − u_i²) + σ_s² u_i²) with u gravity's direction in the IMU's axes (the filter estimates neither a misalignment nor a scale factor apart from a bias along a steady gravity); so an accelerometer's estimate is its bias plus its estimated scale factor times gravity's specific force on the axis, b̂ + ŝ·f, the sum the data observe.",
        &svg,
    );
    html.push_str("<table class=\"metrics\"><tr><th>bias</th><th>unit</th><th>configured</th><th>σ at start</th><th>instability σ</th><th>σ at end</th><th>final estimate</th><th>final (σ)</th><th>largest (σ)</th><th>inside ±3σ throughout</th></tr>\n");
    for b in checks {
        row(
            html,
            &[
                escape(&b.axis),
                b.unit.into(),
                format!("{:.1}", b.center),
                format!("{:.1}", b.init_sd),
                format!("{:.1}", b.instability_sd),
                format!("{:.1}", b.final_sd),
                format!("{:.1}", b.final_estimate),
                format!("{:+.2}", (b.final_estimate - b.center) / b.final_sd),
                format!("{:.2}", b.max_sigmas),
                if b.max_sigmas <= BIAS_SIGMAS {
                    "yes".into()
                } else {
                    "<b>no</b>".into()
                },
            ],
        );
    }
    html.push_str("</table>\n");
    Ok(())
}

/// The data gaps: GNSS gaps and outages, IMU gaps and losses.
pub(crate) fn gaps_section(
    html: &mut String,
    gaps: &[Gap],
    median_fix_interval_s: Option<f64>,
    sync: Option<&SyncReport>,
    summary: Option<&Value>,
) {
    html.push_str("<section id=\"gaps\"><h2>Data gaps</h2>\n");
    match median_fix_interval_s {
        Some(m) => {
            let _ = writeln!(
                html,
                "<p class=\"note\">A GNSS gap: consecutive fixes more than {GAP_FACTOR}× the median interval ({m:.3} s) apart; scheduled outages (fixes withheld by <code>fuse --outage-*</code>, summary.json) are listed too.</p>"
            );
        }
        None => html.push_str("<p class=\"note\">No GNSS fix times (neither --gnss nor gnss_residuals.txt): GNSS gaps not assessed.</p>\n"),
    }
    if gaps.is_empty() {
        html.push_str("<p>No GNSS gap.</p>\n");
    } else {
        let total: f64 = gaps.iter().map(|g| g.end - g.start).sum();
        let _ = writeln!(
            html,
            "<p>{} GNSS gaps, {total:.1} s in all, longest {:.1} s.</p>",
            gaps.len(),
            gaps.iter().map(|g| g.end - g.start).fold(0.0, f64::max)
        );
        html.push_str("<details open><summary>GNSS gaps</summary><table class=\"metrics\"><tr><th>start t (s)</th><th>start SOW</th><th>length (s)</th><th>kind</th></tr>\n");
        for g in gaps.iter().take(200) {
            row(
                html,
                &[
                    format!("{:.2}", g.start),
                    format!("{:.3}", g.start_sow),
                    format!("{:.2}", g.end - g.start),
                    g.kind.into(),
                ],
            );
        }
        html.push_str("</table></details>\n");
        if gaps.len() > 200 {
            let _ = writeln!(html, "<p>… and {} more.</p>", gaps.len() - 200);
        }
    }
    let stats = summary.and_then(|s| s.get("stats"));
    let num = |k: &str| stats.and_then(|s| s.get(k)).and_then(Value::as_f64);
    if let (Some(n), Some(total), Some(max)) = (num("gaps"), num("gap_total_s"), num("max_gap_s")) {
        let _ = writeln!(
            html,
            "<p>IMU: {n:.0} gaps bridged by the fusion (summary.json), {total:.3} s in all, longest {max:.3} s.</p>"
        );
    }
    if let Some(s) = sync {
        let _ = writeln!(
            html,
            "<p>IMU acquisition (sync_report.json): {} samples, {} lost, {} duplicated, {} unstamped.</p>",
            s.records.imu, s.imu.lost, s.imu.duplicated, s.imu.unstamped
        );
    }
    html.push_str("</section>\n");
}

/// The filter's predicted horizontal σ through each gap of a few seconds.
pub(crate) fn drift_section(html: &mut String, gaps: &[Gap], forward: bool, have_std: bool) {
    html.push_str("<section id=\"outage-drift\"><h2>Predicted drift through GNSS gaps</h2>\n");
    let _ = writeln!(
        html,
        "<p class=\"note\">For every GNSS gap or outage of at least {DRIFT_MIN_GAP_S} s: the {} horizontal σ √(σ_n² + σ_e²) at the gap's start and its largest value inside it (just before the first fix after it). This is the drift the filter predicts with its error model. The last columns measure it: the first fix after the gap against the prediction (horizontal offset and NEES, χ²₂ for a consistent filter: 99 % below 9.2), and whether the fix after that confirms the INS drifted (yes) or says the first fix was off (no); – where the fix was less certain than the INS or had no residual line.</p>",
        if forward {
            "forward filter's (forward/std.txt, not the smoother's)"
        } else {
            "filter's (std.txt)"
        }
    );
    let long: Vec<&Gap> = gaps
        .iter()
        .filter(|g| g.end - g.start >= DRIFT_MIN_GAP_S)
        .collect();
    if !have_std {
        html.push_str("<p>No std.txt: not assessed.</p>\n");
    } else if long.is_empty() {
        let _ = writeln!(html, "<p>No GNSS gap of {DRIFT_MIN_GAP_S} s or more.</p>");
    } else {
        html.push_str("<table class=\"metrics\"><tr><th>start t (s)</th><th>length (s)</th><th>kind</th><th>σ_h at start (m)</th><th>σ_h at end (m)</th><th>growth</th><th>3σ_h at end (m)</th><th>first fix after: offset (m)</th><th>NEES</th><th>INS drift confirmed</th></tr>\n");
        for g in long.iter().take(200) {
            let cells = match g.drift {
                Some((a, b)) => [
                    format!("{a:.3}"),
                    format!("{b:.3}"),
                    format!("×{:.1}", b / a.max(1e-9)),
                    format!("{:.2}", 3.0 * b),
                ],
                None => ["–".into(), "–".into(), "–".into(), "–".into()],
            };
            let mut r = vec![
                format!("{:.2}", g.start),
                format!("{:.2}", g.end - g.start),
                g.kind.to_string(),
            ];
            r.extend(cells);
            r.extend(match g.end_test {
                Some(e) => [
                    format!("{:.3}", e.offset_h_m),
                    format!("{:.1}", e.nees),
                    match e.drift_confirmed {
                        Some(true) => "yes".into(),
                        Some(false) => "no".into(),
                        None => "–".into(),
                    },
                ],
                None => ["–".into(), "–".into(), "–".into()],
            });
            row(html, &r);
        }
        html.push_str("</table>\n");
    }
    html.push_str("</section>\n");
}

/// Gathers the evidence.
pub(crate) struct Gathered<'a> {
    pub fixes: &'a [FixWeight],
    pub std: Option<&'a [Vec<f64>]>,
    pub biases: Vec<BiasCheck>,
    pub sync: Option<&'a SyncReport>,
    pub summary: Option<&'a Value>,
    pub time_offset: Option<&'a [Vec<f64>]>,
    pub gaps: &'a [Gap],
    pub written: Option<crate::written::WrittenEvidence>,
    /// [`crate::inputs::incomplete_solution`]'s finding.
    pub incomplete: Option<String>,
    pub innovation: Option<crate::innovation::InnovationEvidence>,
    /// `probe.json` of `navsync process`.
    pub probe: Option<&'a Value>,
    /// The gaps' ends against the forward σ, when measured.
    pub gap_ends: Option<crate::gap_ends::GapEndEvidence>,
}

/// The consistency probe's estimates (`probe.json`).
fn probe_evidence(probe: Option<&Value>) -> Option<quality::ProbeEvidence> {
    let p = probe?;
    let num = |k: &str| p.get(k).and_then(Value::as_f64);
    let time_offset_s = match (num("time_offset_s"), num("time_offset_sd_s")) {
        (Some(o), Some(sd)) if o.is_finite() && sd.is_finite() && sd > 0.0 => Some((o, sd)),
        _ => None,
    };
    let failed = p.get("failed").and_then(Value::as_str).map(str::to_string);
    let lever_arm = p
        .get("lever_arm")
        .and_then(|v| serde_json::from_value(v.clone()).ok());
    Some(quality::ProbeEvidence {
        time_offset_s,
        lever_arm,
        failed,
    })
}

pub(crate) fn evidence(g: Gathered) -> Evidence {
    Evidence {
        fixes: (!g.fixes.is_empty()).then(|| fix_evidence(g.fixes)),
        final_h_sd_m: g.std.and_then(|s| s.last()).map(|r| r[1].hypot(r[2])),
        biases: g.biases,
        sync: sync_evidence(g.sync, g.summary),
        time_offset_sd_s: g.time_offset.and_then(|r| r.last()).map(|r| r[2]),
        alignment: align_evidence(g.summary),
        worst_gap: worst_gap(g.gaps),
        gap_ends: g.gap_ends,
        written: g.written,
        solution_incomplete: g.incomplete,
        innovation: g.innovation,
        antenna_lever_m: g.summary.and_then(|s| triplet(s.get("antenna_lever_m"))),
        probe: probe_evidence(g.probe),
        lever_estimate: g
            .summary
            .and_then(|s| s.get("lever_arm"))
            .and_then(|v| serde_json::from_value(v.clone()).ok()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An accelerometer is judged by b̂ + ŝ·f: a clean simulated ICM-20602
    /// drive's z bias (+38 080 mGal) and scale (+39 618 ppm) cancel along
    /// gravity (sum −772 mGal, inside its 5 750 mGal envelope), where the
    /// bias alone is 6.6σ out; a bias nothing cancels is still out.
    #[test]
    fn an_accelerometer_is_judged_by_bias_plus_scale_times_gravity() {
        let summary = serde_json::json!({"imu_model": {
            "accel_bias_sd_mgal": [100.0, 100.0, 100.0], "accel_scale_sd_ppm": [5000.0, 5000.0, 5000.0],
            "gyro_bias_sd_deg_h": [10.0, 10.0, 10.0], "corr_time_s": 3600.0,
            "init_accel_bias_mgal": [0.0, 0.0, 0.0], "init_accel_bias_sd_mgal": [3000.0, 3000.0, 3000.0],
            "init_gyro_bias_deg_h": [0.0, 0.0, 0.0], "init_gyro_bias_sd_deg_h": [360.0, 360.0, 360.0]}});
        let row = |bias_z: f64, scale_z: f64| {
            let mut r = vec![0.0; 13];
            r[6] = bias_z;
            r[12] = scale_z;
            r
        };
        let z = |rows: &[Vec<f64>]| {
            bias_checks(Some(&summary), Some(rows), Some([0.0, 0.0]))
                .into_iter()
                .find(|b| b.axis == "accel z")
                .expect("accel z")
        };
        let ridge = z(&[row(0.0, 0.0), row(38_080.0, 39_618.0)]);
        assert!(ridge.max_sigmas < 0.2, "{ridge:?}");
        assert!((ridge.final_estimate - (38_080.0 - 39_618e-6 * 9.806_65e5)).abs() < 1e-6);
        let bias_only = z(&[row(0.0, 0.0), row(38_080.0, 0.0)]);
        assert!(bias_only.max_sigmas > 6.0, "{bias_only:?}");
        // A gyro is judged by its bias alone.
        let mut r = row(0.0, 0.0);
        r[3] = 2000.0;
        r[9] = 1e6;
        let gz = bias_checks(Some(&summary), Some(&[r]), Some([0.0, 0.0]))
            .into_iter()
            .find(|b| b.axis == "gyro z")
            .expect("gyro z");
        assert!(gz.max_sigmas > 5.0, "{gz:?}");
    }

    fn fix(sow: f64, reason: &str) -> FixWeight {
        FixWeight {
            sow,
            innovation: [0.0, 0.0, 0.0],
            sd: [0.01; 3],
            nis: 1.0,
            weight: [1.0; 3],
            status: if reason == "-" || reason == "persisted" {
                "used"
            } else {
                "rejected"
            }
            .into(),
            reason: reason.into(),
        }
    }

    /// A false fix (jump, then run), stale repeats, and a false fix the
    /// INS could not resolve (followed again: persisted) are three
    /// episodes, with their excluded and persisted fixes counted.
    #[test]
    fn fault_episodes_are_read_back_from_the_reasons() {
        let reasons = [
            "-",
            "jump",
            "run",
            "run",
            "-",
            "stale",
            "stale",
            "-",
            "jump",
            "run",
            "persisted",
            "persisted",
            "-",
            "outlier",
        ];
        let fixes: Vec<FixWeight> = reasons
            .iter()
            .enumerate()
            .map(|(i, r)| fix(100.0 + i as f64, r))
            .collect();
        let spans = fault_spans(&fixes);
        let got: Vec<(f64, f64, usize, &str, usize)> = spans
            .iter()
            .map(|s| (s.start_sow, s.end_sow, s.excluded, s.kind, s.persisted))
            .collect();
        assert_eq!(
            got,
            vec![
                (101.0, 103.0, 3, "jump", 0),
                (105.0, 106.0, 2, "stale", 0),
                (108.0, 109.0, 2, "jump", 2),
            ]
        );
        let e = fault_evidence(&fixes);
        assert_eq!((e.episodes, e.excluded, e.persisted), (3, 7, 2));
        // Shaded: two resolved, one unresolved; a one-fix width is visible.
        let [ok, unresolved] = fault_shades(&spans, 100.0, 14.0);
        assert_eq!(ok.spans, vec![(1.0, 3.0), (5.0, 6.0)]);
        assert_eq!(unresolved.spans, vec![(8.0, 9.0)]);
        let [one, _] = fault_shades(
            &spans[..1]
                .iter()
                .map(|s| FaultSpan {
                    end_sow: s.start_sow,
                    ..s.clone()
                })
                .collect::<Vec<_>>(),
            100.0,
            1000.0,
        );
        assert!((one.spans[0].1 - one.spans[0].0 - 3.0).abs() < 1e-9);
        let mut html = String::new();
        fault_table(&mut html, &spans, 100.0);
        assert!(html.contains("GNSS fault episodes: 3 (7 excluded fixes; 1 followed again"));
        // No episodes: no table.
        let mut empty = String::new();
        fault_table(&mut empty, &[], 100.0);
        assert!(empty.is_empty());
    }
}
