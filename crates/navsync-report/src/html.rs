//! The report page: metrics tables and the figures, one HTML file with the
//! SVG inline (no scripts, no network).

use std::fmt::Write as _;

use navsync::eval::{EvalReport, parse_outages};
use navsync::timing::SyncReport;
use navsync::{Diagnostics, Error};

use crate::inputs::{
    Epochs, FixWeight, IMU_ERR_LAYOUT, ReportInputs, STD_LAYOUT, TIME_OFFSET_LAYOUT,
    incomplete_solution, read_fix_weights, read_gnss, read_json_object, read_solution,
    read_summary, read_sync_report, read_table, rel_s, score,
};
use crate::plot::{
    self, AXES, BLUE, Band, Figure, GREY, Line, ORANGE, OUTAGE, PURPLE, Panel, RED, Shade,
    Timeline, Trajectory,
};
use crate::quality::{self, Verdict};
use crate::sections;

/// Points per plotted series at most.
pub(crate) const MAX_POINTS: usize = 1200;
/// Figure width (px).
pub(crate) const WIDTH: u32 = 1100;

/// A built report.
pub struct Report {
    pub html: String,
    /// The scores shown, as `navsync eval` computes them (with a truth).
    pub eval: Option<EvalReport>,
    /// The quality verdict at the top of the page.
    pub verdict: Verdict,
    /// Lines skipped in the navigation and truth files (as `navsync eval`).
    pub diagnostics: Diagnostics,
}

/// Escapes text for HTML.
pub(crate) fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn lighter(c: plotters::style::RGBColor) -> plotters::style::RGBColor {
    let m = |v: u8| (f64::from(v) + 0.55 * (255.0 - f64::from(v))) as u8;
    plotters::style::RGBColor(m(c.0), m(c.1), m(c.2))
}

/// Contiguous runs of `flag` over `t` as (start, end) spans.
fn spans_where(t: &[f64], flag: &[bool]) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut start: Option<f64> = None;
    for (i, (&ti, &f)) in t.iter().zip(flag).enumerate() {
        match (f, start) {
            (true, None) => start = Some(ti),
            (false, Some(s)) => {
                out.push((s, t[i - 1].max(s)));
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(s), Some(&e)) = (start, t.last()) {
        out.push((s, e));
    }
    out
}

/// A downsampled (t, value) series.
fn series(t: &[f64], v: impl Fn(usize) -> f64) -> Vec<(f64, f64)> {
    let k = plot::stride(t.len(), MAX_POINTS);
    (0..t.len()).step_by(k).map(|i| (t[i], v(i))).collect()
}

/// One rows-per-epoch table resampled to at most [`MAX_POINTS`] rows, with
/// times relative to `t0_sow`.
pub(crate) struct Rows {
    pub(crate) t: Vec<f64>,
    pub(crate) rows: Vec<Vec<f64>>,
}

impl Rows {
    pub(crate) fn new(rows: Vec<Vec<f64>>, t0_sow: f64) -> Rows {
        let k = plot::stride(rows.len(), MAX_POINTS);
        let rows: Vec<Vec<f64>> = rows.into_iter().step_by(k).collect();
        Rows {
            t: rows.iter().map(|r| rel_s(r[0], t0_sow)).collect(),
            rows,
        }
    }
    pub(crate) fn col(&self, c: usize, scale: f64) -> Vec<(f64, f64)> {
        self.t
            .iter()
            .zip(&self.rows)
            .map(|(&t, r)| (t, r[c] * scale))
            .collect()
    }
    fn band(&self, c: usize, sigmas: f64) -> Vec<(f64, f64, f64)> {
        self.t
            .iter()
            .zip(&self.rows)
            .map(|(&t, r)| (t, -sigmas * r[c], sigmas * r[c]))
            .collect()
    }
}

pub(crate) fn section(html: &mut String, id: &str, title: &str, note: &str, svg: &str) {
    let _ = write!(
        html,
        "<section id=\"{id}\"><h2>{}</h2>\n{}<figure>{svg}</figure></section>\n",
        escape(title),
        if note.is_empty() {
            String::new()
        } else {
            format!("<p class=\"note\">{}</p>\n", escape(note))
        }
    );
}

/// A navigation error quantity: its components and where its σ are in
/// std.txt.
struct Quantity {
    name: &'static str,
    unit: &'static str,
    comps: [&'static str; 3],
    std_col0: usize,
}

const NED: [&str; 3] = ["north", "east", "down"];
const POSITION: Quantity = Quantity {
    name: "position",
    unit: "m",
    comps: NED,
    std_col0: 1,
};
const VELOCITY: Quantity = Quantity {
    name: "velocity",
    unit: "m/s",
    comps: NED,
    std_col0: 4,
};
const ATTITUDE: Quantity = Quantity {
    name: "attitude",
    unit: "deg",
    comps: ["roll", "pitch", "yaw"],
    std_col0: 7,
};

/// The forward filter's errors and σ, drawn behind a smoothed solution.
struct ForwardSeries<'a> {
    ep: &'a Epochs,
    std: Option<&'a Rows>,
}

/// Light orange: the forward filter's ±3σ behind a smoothed solution's.
const FORWARD_BAND: plotters::style::RGBColor = plotters::style::RGBColor(190, 160, 230);

fn error_figure(
    ep: &Epochs,
    std: Option<&Rows>,
    shades: &[Shade],
    q: &Quantity,
    forward: Option<&ForwardSeries>,
    value: impl Fn(&Epochs, usize, usize) -> f64,
) -> Result<String, Error> {
    let (quantity, unit, comps, std_col0) = (q.name, q.unit, q.comps, q.std_col0);
    let x1 = ep.t.last().copied().unwrap_or(1.0).max(1e-3);
    let smoothed = forward.is_some();
    let panels = (0..3)
        .map(|c| {
            let mut lines = Vec::new();
            let mut bands = Vec::new();
            if let Some(f) = forward {
                if let Some(s) = f.std {
                    bands.push(Band {
                        name: "forward filter ±3σ".into(),
                        color: FORWARD_BAND,
                        pts: s.band(std_col0 + c, 3.0),
                    });
                }
                lines.push(Line {
                    name: "forward filter − truth".into(),
                    color: lighter(AXES[c]),
                    width: 1,
                    pts: series(&f.ep.t, |i| value(f.ep, i, c)),
                });
            }
            if let Some(s) = std {
                bands.push(Band {
                    name: if smoothed {
                        "smoother ±3σ"
                    } else {
                        "filter ±3σ"
                    }
                    .into(),
                    color: GREY,
                    pts: s.band(std_col0 + c, 3.0),
                });
            }
            lines.push(Line {
                name: if smoothed {
                    "smoothed − truth"
                } else {
                    "solution − truth"
                }
                .into(),
                color: AXES[c],
                width: 1,
                pts: series(&ep.t, |i| value(ep, i, c)),
            });
            Panel {
                title: format!("{quantity} error, {}", comps[c]),
                y_label: format!("{} ({unit})", comps[c]),
                lines,
                bands,
                dots: Vec::new(),
                y_range: None,
            }
        })
        .collect();
    plot::time_series(&Figure {
        x_label: "time since the first epoch (s)".into(),
        x_range: (0.0, x1),
        shades: shades.to_vec(),
        panels,
        width: WIDTH,
        panel_height: 210,
    })
}

pub(crate) fn row(html: &mut String, cells: &[String]) {
    html.push_str("<tr>");
    for c in cells {
        let _ = write!(html, "<td>{c}</td>");
    }
    html.push_str("</tr>\n");
}

fn f4(v: f64) -> String {
    format!("{v:.4}")
}

/// The metrics tables (values as `navsync eval` prints them).
fn metrics_tables(html: &mut String, e: &EvalReport) {
    html.push_str("<table class=\"metrics\"><tr><th>error (solution − truth)</th><th>unit</th><th>RMS</th><th>max |·|</th><th>mean</th></tr>\n");
    for (name, unit, s) in e.rows() {
        row(
            html,
            &[
                name.to_string(),
                unit.to_string(),
                f4(s.rms),
                f4(s.max),
                f4(s.mean),
            ],
        );
    }
    html.push_str("</table>\n");
    let _ = writeln!(
        html,
        "<p>{} epochs compared ({} without truth).</p>",
        e.epochs_compared, e.epochs_without_truth
    );
    if !e.outages.is_empty() {
        html.push_str("<table class=\"metrics\"><tr><th>GNSS outage start (sow)</th><th>length (s)</th><th>max horizontal drift (m)</th><th>max 3D drift (m)</th></tr>\n");
        for o in &e.outages {
            row(
                html,
                &[
                    format!("{:.3}", o.start_sow),
                    format!("{:.1}", o.len_s),
                    format!("{:.3}", o.max_horizontal_m),
                    format!("{:.3}", o.max_3d_m),
                ],
            );
        }
        html.push_str("</table>\n");
        if let (Some(h), Some(d)) = (e.outage_rms_max_horizontal_m, e.outage_rms_max_3d_m) {
            let _ = writeln!(
                html,
                "<p>RMS over outages of the maximum drift: horizontal <b>{h:.3} m</b>, 3D {d:.3} m (Niu et al. 2010 protocol, as KF-GINS).</p>"
            );
        }
    }
}

/// The forward filter against the smoothed solution: RMS of each error and
/// the outage drift, side by side.
fn forward_comparison(html: &mut String, forward: &EvalReport, smoothed: &EvalReport) {
    html.push_str("<h3>Smoothed against the forward filter</h3>\n<table class=\"metrics\"><tr><th>RMS error</th><th>unit</th><th>forward filter</th><th>smoothed</th><th>ratio</th></tr>\n");
    for ((name, unit, f), (_, _, s)) in forward.rows().into_iter().zip(smoothed.rows()) {
        row(
            html,
            &[
                name.to_string(),
                unit.to_string(),
                f4(f.rms),
                f4(s.rms),
                format!("{:.3}", s.rms / f.rms),
            ],
        );
    }
    if let (Some(f), Some(s)) = (
        forward.outage_rms_max_horizontal_m,
        smoothed.outage_rms_max_horizontal_m,
    ) {
        row(
            html,
            &[
                "outage drift (RMS of max horizontal)".into(),
                "m".into(),
                format!("{f:.3}"),
                format!("{s:.3}"),
                format!("{:.3}", s / f),
            ],
        );
    }
    html.push_str("</table>\n<p class=\"note\">Forward–backward smoothing: Rauch, Tung &amp; Striebel, “Maximum likelihood estimates of linear dynamic systems”, AIAA Journal 3(8), 1965.</p>\n");
}

fn sync_tables(html: &mut String, s: &SyncReport, t0_sow: f64) {
    html.push_str("<table class=\"metrics kv\">\n");
    let mut kv = |k: &str, v: String| row(html, &[escape(k), v]);
    kv(
        "mode",
        format!(
            "{} ({})",
            s.mode,
            if s.causal {
                "causal"
            } else {
                "post-processing"
            }
        ),
    );
    kv(
        "records",
        format!(
            "{} imu, {} pps, {} gnss",
            s.records.imu, s.records.pps, s.records.gnss
        ),
    );
    if let Some(f) = &s.counter.freq_error_ppm {
        kv(
            "counter frequency error",
            format!("{:.2} ppm ({:.2} … {:.2})", f.mean, f.min, f.max),
        );
    }
    if let Some(p) = &s.pps {
        let c = &p.counts;
        let rejected: Vec<String> = [
            (c.rejected_spurious, "spurious"),
            (c.rejected_displaced, "displaced"),
            (c.rejected_duplicate, "duplicate"),
            (c.rejected_unconfirmed, "unconfirmed"),
            (c.rejected_acquisition, "at acquisition"),
        ]
        .iter()
        .filter(|(n, _)| *n > 0)
        .map(|(n, what)| format!("{n} {what}"))
        .collect();
        kv(
            "1PPS pulses",
            format!(
                "{} received, {} accepted{}",
                c.received,
                c.accepted,
                if rejected.is_empty() {
                    String::new()
                } else {
                    format!("; rejected {}", rejected.join(", "))
                }
            ),
        );
    }
    for h in &s.holdover {
        kv(
            "holdover",
            format!(
                "t = {} s for {:.1} s, bound ≤ {:.2} µs",
                plot::tick(rel_s(h.start.sow, t0_sow), 1),
                h.duration_s,
                h.max_bound_us
            ),
        );
    }
    if let (Some(m), Some(x)) = (s.stamp_bound_us.mean, s.stamp_bound_us.max) {
        kv(
            "IMU stamp-error bound",
            format!("mean {m:.3} µs, max {x:.3} µs"),
        );
    }
    if let Some(t) = &s.truth {
        kv(
            "IMU stamps vs truth",
            format!(
                "<b>RMS {:.3} µs</b>, max {:.3} µs; {:.2} % within bound",
                t.rms_us,
                t.max_abs_us,
                100.0 * t.within_bound
            ),
        );
    }
    let l = &s.gnss.latency_ms;
    if let (Some(a), Some(m), Some(b)) = (l.min, l.median, l.max) {
        kv(
            "GNSS latency",
            format!("min {a:.1}, median {m:.1}, max {b:.1} ms"),
        );
    }
    kv(
        "IMU",
        format!(
            "{:.6} Hz; lost {}, duplicated {}, unstamped {}",
            s.imu.rate_hz.unwrap_or(f64::NAN),
            s.imu.lost,
            s.imu.duplicated,
            s.imu.unstamped
        ),
    );
    if let Some(sw) = &s.software {
        kv("software sync", escape(&sw.describe()));
        kv("not observable", escape(&sw.unobservable));
    }
    if let Some(h) = &s.hybrid {
        kv("hybrid sync", escape(&h.describe()));
        kv("not observable", escape(&h.unobservable));
    }
    if let Some(m) = &s.marks {
        kv("receiver time marks", escape(&m.describe()));
    }
    for f in &s.implausible {
        kv(
            "implausible",
            format!(
                "<span class=\"grade poor\">{}</span>: {}; fix: {}",
                escape(&f.what),
                escape(&f.cause),
                escape(&f.fix)
            ),
        );
    }
    html.push_str("</table>\n");
}

/// Builds the report.
pub fn build(inp: &ReportInputs) -> Result<Report, Error> {
    if let Some(t) = inp.time_offset_truth_s
        && !t.is_finite()
    {
        return Err(Error::Invalid(format!(
            "true time offset {t} s: expected a finite number"
        )));
    }
    let mut diag = Diagnostics::with_cap(100);
    let summary = inp.summary.as_deref().map(read_summary).transpose()?;
    let probe = inp
        .probe
        .as_deref()
        .map(|p| read_json_object(p, "navsync process's probe.json"))
        .transpose()?;
    let outages = if inp.outages.is_empty() {
        let text = summary
            .as_ref()
            .and_then(|s| s.get("outages"))
            .and_then(|v| v.as_str())
            .unwrap_or("");
        parse_outages(text, 0).map_err(|e| match (e, &inp.summary) {
            (Error::Invalid(m), Some(p)) => Error::config(p, format!("\"outages\": {m}")),
            (e, _) => e,
        })?
    } else {
        inp.outages.clone()
    };
    let (eval, ep) = match &inp.truth {
        Some(truth) => {
            let (e, ep) = score(truth, &inp.nav, &outages, &mut diag)?;
            (Some(e), ep)
        }
        None => (None, read_solution(&inp.nav, &mut diag)?),
    };
    let t0 = ep.t0_sow;
    let x1 = ep.t.last().copied().unwrap_or(1.0).max(1e-3);
    let outage_spans: Vec<(f64, f64)> = outages
        .iter()
        .map(|w| {
            let a = rel_s(w.start.sow(), t0);
            (a, a + w.duration_s)
        })
        .collect();
    let outage_shade = Shade {
        name: "GNSS outage".into(),
        color: OUTAGE,
        spans: outage_spans.clone(),
    };
    let table = |p: &Option<std::path::PathBuf>, columns: usize, layout: &str| {
        p.as_deref()
            .map(|p| read_table(p, columns, layout))
            .transpose()
    };
    let rows = |p: &Option<std::path::PathBuf>, columns: usize, layout: &str| {
        table(p, columns, layout).map(|r| r.map(|r| Rows::new(r, t0)))
    };
    // Full-rate σ (std.txt), and the forward filter's when smoothed: the
    // predicted σ through gaps is the filter's, not the smoother's.
    let std_full = table(&inp.std, 22, STD_LAYOUT)?;
    let forward_std_full = table(&inp.forward_std, 22, STD_LAYOUT)?;
    let std = std_full.clone().map(|r| Rows::new(r, t0));
    // A smoothed solution's forward run, scored the same way.
    let forward = match (&inp.forward_nav, &inp.truth) {
        (Some(p), Some(truth)) => {
            let (fe, fep) = score(truth, p, &outages, &mut diag)?;
            Some((fe, fep, forward_std_full.clone().map(|r| Rows::new(r, t0))))
        }
        _ => None,
    };
    let imu_err_full = table(&inp.imu_err, 13, IMU_ERR_LAYOUT)?;
    let imu_err = imu_err_full.clone().map(|r| Rows::new(r, t0));
    let imu_err_truth = rows(&inp.imu_err_truth, 13, IMU_ERR_LAYOUT)?;
    let offset = inp
        .time_offset
        .as_deref()
        .map(|p| read_table(p, 4, TIME_OFFSET_LAYOUT))
        .transpose()?;
    let sync = inp
        .sync_report
        .as_deref()
        .map(read_sync_report)
        .transpose()?;
    let gnss = match (&inp.gnss, ep.origin) {
        (Some(p), Some(o)) => read_gnss(p, &o, &mut diag)?,
        _ => Vec::new(),
    };

    // The evidence for the verdict and the sections without a truth.
    let fixes = inp
        .gnss_residuals
        .as_deref()
        .map(read_fix_weights)
        .transpose()?
        .unwrap_or_default();
    let fault_spans = sections::fault_spans(&fixes);
    let [fault_shade, unresolved_shade] = sections::fault_shades(&fault_spans, t0, x1);
    let sigma_h = forward_std_full
        .as_ref()
        .or(std_full.as_ref())
        .map(|s| sections::horizontal_sigma(s, t0))
        .unwrap_or_default();
    let mut fix_times: Vec<f64> = if gnss.is_empty() {
        fixes.iter().map(|f| rel_s(f.sow, t0)).collect()
    } else {
        gnss.iter().map(|g| rel_s(g.0, t0)).collect()
    };
    fix_times.sort_by(f64::total_cmp);
    let median_fix_interval_s = {
        let mut dt: Vec<f64> = fix_times.windows(2).map(|w| w[1] - w[0]).collect();
        dt.sort_by(f64::total_cmp);
        dt.get(dt.len() / 2).copied()
    };
    let mut gaps = sections::gaps(&fix_times, &outage_spans, &sigma_h, t0);
    // The written file and the forward pass it came from (the same file
    // when not smoothed): heading, velocity and tilt for the checks below.
    let (track, forward_track) = match ep.origin {
        Some(o) => (
            Some(crate::written::Track::read(&inp.nav, &o, &mut diag)?),
            inp.forward_nav
                .as_deref()
                .map(|p| crate::written::Track::read(p, &o, &mut diag))
                .transpose()?,
        ),
        None => (None, None),
    };
    // The written file itself against the fixes and the forward pass.
    let written = match (&inp.gnss, ep.origin, &track) {
        (Some(g), Some(o), Some(track)) => {
            let fixes = crate::written::read_fixes(g, &o, &mut diag)?;
            crate::written::evidence(track, forward_track.as_ref(), &fixes, std_full.as_deref())
        }
        _ => None,
    };
    let filter_track = forward_track.as_ref().or(track.as_ref());
    let filter_std = forward_std_full.as_deref().or(std_full.as_deref());
    // The first fix after each gap against the forward filter's σ.
    let gap_ends = filter_std.and_then(|s| {
        sections::test_gap_ends(&mut gaps, &fixes, s, t0);
        let ends: Vec<_> = gaps.iter().filter_map(|g| g.end_test).collect();
        crate::gap_ends::evidence(&ends, inp.forward_nav.is_none())
    });
    let tilt = filter_track.and_then(|t| t.median_roll_pitch_rad());
    let biases = sections::bias_checks(summary.as_ref(), imu_err_full.as_deref(), tilt);
    let innovation = match (filter_track, filter_std) {
        (Some(t), Some(s)) => crate::innovation::analyse(&crate::innovation::samples(&fixes, t, s)),
        _ => None,
    };
    let verdict = quality::assess(&sections::evidence(sections::Gathered {
        fixes: &fixes,
        std: std_full.as_deref(),
        biases: biases.clone(),
        sync: sync.as_ref(),
        summary: summary.as_ref(),
        time_offset: offset.as_deref(),
        gaps: &gaps,
        written,
        incomplete: incomplete_solution(&inp.nav, &ep, summary.as_ref()),
        innovation,
        probe: probe.as_ref(),
        gap_ends,
    }));
    let gap_shade = Shade {
        name: "GNSS gap or outage".into(),
        color: OUTAGE,
        spans: gaps.iter().map(|g| (g.start, g.end)).collect(),
    };

    let mut html = String::with_capacity(1 << 20);
    let title = if inp.title.is_empty() {
        "navsync report"
    } else {
        inp.title.as_str()
    };
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>{t}</title>\n<style>\n\
         body{{font-family:sans-serif;max-width:1140px;margin:1em auto;padding:0 1em;color:#222}}\n\
         h1{{font-size:1.5em}} h2{{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}}\n\
         table.metrics{{border-collapse:collapse;margin:.5em 0}} table.metrics td,table.metrics th{{border:1px solid #ccc;padding:.2em .6em;text-align:right}}\n\
         table.metrics td:first-child,table.metrics th:first-child{{text-align:left}} table.metrics th{{background:#f2f2f2}} table.kv td,table.kv th{{text-align:left}} table.kv td:first-child{{white-space:nowrap}}\n\
         .cols{{display:flex;flex-wrap:wrap;gap:0 2em;align-items:flex-start}} .cols>div{{flex:1 1 480px;min-width:0}} h3{{font-size:1.05em;margin:.6em 0 .3em}}\n\
         figure{{margin:.5em 0}} figure svg{{max-width:100%;height:auto}} .note{{color:#555;font-size:.92em}} code{{font-size:.95em}}\n\
         .grade{{padding:.05em .5em;border-radius:.3em}} .grade.good{{background:#cdeccd}} .grade.caution{{background:#ffe8a8}} .grade.poor{{background:#f6c4c4}}\n\
         </style></head><body>\n<h1>{t}</h1>\n",
        t = escape(title)
    );
    match &inp.truth {
        Some(truth) => {
            let _ = writeln!(
                html,
                "<p class=\"note\">navsync {} — solution <code>{}</code> against <code>{}</code>; first epoch GPS week {} SOW {:.3} (t = 0 below). Errors are solution − truth, with the truth interpolated to each epoch; figures show at most {} points per curve.</p>",
                env!("CARGO_PKG_VERSION"),
                escape(&inp.nav.display().to_string()),
                escape(&truth.display().to_string()),
                ep.week,
                t0,
                MAX_POINTS
            );
        }
        None => {
            let _ = writeln!(
                html,
                "<p class=\"note\">navsync {} — solution <code>{}</code> without a reference trajectory: judged from the filter's own statistics and the files beside it; first epoch GPS week {} SOW {:.3} (t = 0 below); figures show at most {} points per curve.</p>",
                env!("CARGO_PKG_VERSION"),
                escape(&inp.nav.display().to_string()),
                ep.week,
                t0,
                MAX_POINTS
            );
        }
    }
    sections::verdict_section(&mut html, &verdict, eval.is_some());

    // Metrics first.
    let _ = writeln!(
        html,
        "<section id=\"metrics\"><h2>{}</h2>\n<div class=\"cols\"><div>",
        if eval.is_some() { "Metrics" } else { "Summary" }
    );
    if let Some(eval) = &eval {
        metrics_tables(&mut html, eval);
        if let Some((fe, _, _)) = &forward {
            forward_comparison(&mut html, fe, eval);
        }
    }
    let final_offset = offset.as_ref().and_then(|r| r.last()).map(|r| (r[1], r[2]));
    if let Some((o, sd)) = final_offset {
        let truth = inp
            .time_offset_truth_s
            .map(|t| {
                format!(
                    "; truth {:.3} ms, error {:+.3} ms ({:+.1}σ)",
                    t * 1e3,
                    (o - t) * 1e3,
                    (o - t) / sd
                )
            })
            .unwrap_or_default();
        let _ = writeln!(
            html,
            "<p>Time offset (GNSS time tag − true validity), final estimate: <b>{:.3} ms ± {:.3} ms</b> (1σ){truth}.</p>",
            o * 1e3,
            sd * 1e3
        );
    }
    if let Some(s) = &summary {
        let stats = s.get("stats");
        let get = |k: &str| {
            stats
                .and_then(|st| st.get(k))
                .and_then(|v| v.as_u64())
                .map_or("-".to_string(), |v| v.to_string())
        };
        let _ = writeln!(
            html,
            "<p>Fusion: {} IMU samples, GNSS fixes {} used, {} rejected by the innovation gate, {} withheld by scheduled outages.</p>",
            get("imu_samples"),
            get("gnss_fixes_used"),
            get("gnss_fixes_rejected"),
            s.get("gnss_fixes_withheld_by_outages")
                .and_then(|v| v.as_u64())
                .unwrap_or(0)
        );
    }
    html.push_str("</div>\n");
    if let Some(s) = &sync {
        html.push_str("<div><h3>Synchronization</h3>\n");
        sync_tables(&mut html, s, t0);
        html.push_str("</div>\n");
    }
    html.push_str("</div></section>\n");

    // Trajectory.
    let k = plot::stride(ep.t.len(), 3000);
    let idx: Vec<usize> = (0..ep.t.len()).step_by(k).collect();
    let with_truth = !ep.truth_ne.is_empty();
    let truth_ne: Vec<(f64, f64)> = idx
        .iter()
        .filter_map(|&i| ep.truth_ne.get(i).copied())
        .collect();
    let sol_ne: Vec<(f64, f64)> = idx.iter().map(|&i| ep.sol_ne[i]).collect();
    let inside = |a: f64, b: f64| -> Vec<usize> {
        (0..ep.t.len())
            .filter(|&i| ep.t[i] >= a && ep.t[i] <= b)
            .step_by(plot::stride(ep.t.len(), 3000))
            .collect()
    };
    let gnss_ne: Vec<(f64, f64)> = gnss.iter().map(|g| (g.1, g.2)).collect();
    let svg = plot::trajectory(
        &Trajectory {
            truth: &truth_ne,
            solution: &sol_ne,
            gnss: &gnss_ne,
            truth_in_outage: outage_spans
                .iter()
                .filter(|_| with_truth)
                .map(|&(a, b)| inside(a, b).iter().map(|&i| ep.truth_ne[i]).collect())
                .collect(),
            solution_in_outage: outage_spans
                .iter()
                .filter(|_| with_truth)
                .map(|&(a, b)| inside(a, b).iter().map(|&i| ep.sol_ne[i]).collect())
                .collect(),
        },
        900,
        720,
    )?;
    section(
        &mut html,
        "trajectory",
        "Trajectory",
        if with_truth {
            "North/east of the first truth position, equal scales."
        } else {
            "North/east of the first solution position, equal scales; GNSS fixes as dots when --gnss is given."
        },
        &svg,
    );

    let shades = [
        outage_shade.clone(),
        fault_shade.clone(),
        unresolved_shade.clone(),
    ];
    // The errors against the truth.
    if eval.is_some() {
        let nav_note = if std.is_some() {
            "Grey band: the filter's ±3σ (std.txt); shaded: GNSS outages and GNSS fault episodes."
        } else {
            "Shaded: GNSS outages and GNSS fault episodes (no std.txt given: no ±3σ bands)."
        };
        let fwd_series = forward.as_ref().map(|(_, fep, fstd)| ForwardSeries {
            ep: fep,
            std: fstd.as_ref(),
        });
        let nav_note = if fwd_series.is_some() {
            "Smoothed solution (dark) with the smoother's ±3σ (grey), the forward filter's errors (light) with its ±3σ (lilac), from forward/; shaded: GNSS outages and GNSS fault episodes."
        } else {
            nav_note
        };
        let fw = fwd_series.as_ref();
        let svg = error_figure(&ep, std.as_ref(), &shades, &POSITION, fw, |e, i, c| {
            e.pos_err[i][c]
        })?;
        section(&mut html, "position", "Position error", nav_note, &svg);
        let svg = error_figure(&ep, std.as_ref(), &shades, &VELOCITY, fw, |e, i, c| {
            e.vel_err[i][c]
        })?;
        section(&mut html, "velocity", "Velocity error", nav_note, &svg);
        let svg = error_figure(&ep, std.as_ref(), &shades, &ATTITUDE, fw, |e, i, c| {
            e.att_err[i][c]
        })?;
        section(
            &mut html,
            "attitude",
            "Attitude error",
            "Roll/pitch/yaw differences; the band is the φ-angle σ (std.txt), which equals the Euler-angle σ near level attitude.",
            &svg,
        );
    }

    if let Some(est) = &imu_err {
        let names = [
            ("gyro bias", "deg/h"),
            ("accelerometer bias", "mGal"),
            ("gyro scale-factor error", "ppm"),
            ("accelerometer scale-factor error", "ppm"),
        ];
        let panels = names
            .iter()
            .enumerate()
            .map(|(g, (name, unit))| {
                let mut lines = Vec::new();
                for (a, axis) in ["x", "y", "z"].iter().enumerate() {
                    let c = 1 + 3 * g + a;
                    if let Some(tr) = &imu_err_truth {
                        lines.push(Line {
                            name: format!("{axis} truth"),
                            color: lighter(AXES[a]),
                            width: 2,
                            pts: tr.col(c, 1.0),
                        });
                    }
                    lines.push(Line {
                        name: format!("{axis} estimate"),
                        color: AXES[a],
                        width: 2,
                        pts: est.col(c, 1.0),
                    });
                }
                Panel {
                    title: name.to_string(),
                    y_label: format!("{name} ({unit})"),
                    lines,
                    bands: Vec::new(),
                    dots: Vec::new(),
                    y_range: None,
                }
            })
            .collect();
        let svg = plot::time_series(&Figure {
            x_label: "time since the first epoch (s)".into(),
            x_range: (0.0, x1),
            shades: shades.to_vec(),
            panels,
            width: WIDTH,
            panel_height: 230,
        })?;
        // With misalignment states the fusion's summary lists them.
        let misaligned = summary
            .as_ref()
            .and_then(|s| s.get("final_gyro_misalign_deg"))
            .is_some_and(|v| !v.is_null());
        let text = match (imu_err_truth.is_some(), misaligned) {
            (true, true) => {
                "Estimates (imu_err.txt, dark) against the simulator's true errors (imu_err_truth.txt, light), body axes x/y/z. The axis misalignments were estimated as 12 more states (summary.json: final_gyro_misalign_deg, final_accel_misalign_deg)."
            }
            (true, false) => {
                "Estimates (imu_err.txt, dark) against the simulator's true errors (imu_err_truth.txt, light), body axes x/y/z. If the IMU has axis misalignment and the fusion did not estimate it (navsync fuse --misalignment), it shows up in these estimates: a 0.05° tilt of a horizontal accelerometer reads g·0.05° ≈ 860 mGal."
            }
            (false, _) => "Estimates (imu_err.txt), body axes x/y/z.",
        };
        section(&mut html, "imu", "IMU error estimates", text, &svg);
    }
    let new_shades = [gap_shade.clone()];
    if let (false, Some(est)) = (biases.is_empty(), &imu_err) {
        sections::imu_envelope_section(&mut html, &biases, est, x1, &new_shades)?;
    }

    if !fixes.is_empty() {
        gnss_weighting_section(&mut html, &fixes, t0, x1, &shades)?;
        sections::fault_table(&mut html, &fault_spans, t0);
        sections::innovation_section(&mut html, &fixes, std_full.as_deref(), t0, x1, &new_shades)?;
        sections::nis_section(&mut html, &fixes, t0, x1, &new_shades)?;
    }
    if let Some(s) = &std {
        sections::sigma_section(&mut html, s, x1, &new_shades, inp.forward_nav.is_some())?;
    }

    if let Some(rows) = &offset {
        let t: Vec<f64> = rows.iter().map(|r| rel_s(r[0], t0)).collect();
        let sd_final = rows.last().map_or(0.0, |r| r[2]);
        // Scale on the converged part: σ within 3× its final value.
        let conv: Vec<&Vec<f64>> = rows.iter().filter(|r| r[2] <= 3.0 * sd_final).collect();
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for r in &conv {
            lo = lo.min(r[1] - 3.0 * r[2]);
            hi = hi.max(r[1] + 3.0 * r[2]);
        }
        if let Some(tt) = inp.time_offset_truth_s {
            lo = lo.min(tt);
            hi = hi.max(tt);
        }
        let pad = 0.15 * (hi - lo).max(1e-4);
        let held: Vec<bool> = rows.iter().map(|r| r[3] == 0.0).collect();
        let k = plot::stride(rows.len(), MAX_POINTS);
        let mut lines = vec![Line {
            name: "estimate τ̂".into(),
            color: BLUE,
            width: 2,
            pts: rows
                .iter()
                .step_by(k)
                .map(|r| (rel_s(r[0], t0), r[1] * 1e3))
                .collect(),
        }];
        if let Some(tt) = inp.time_offset_truth_s {
            lines.push(Line {
                name: "truth".into(),
                color: plotters::style::RGBColor(0, 0, 0),
                width: 1,
                pts: vec![(0.0, tt * 1e3), (x1, tt * 1e3)],
            });
        }
        let svg = plot::time_series(&Figure {
            x_label: "time since the first epoch (s)".into(),
            x_range: (0.0, x1),
            shades: vec![
                Shade {
                    name: "τ̂ held (no information)".into(),
                    color: PURPLE,
                    spans: spans_where(&t, &held),
                },
                outage_shade.clone(),
            ],
            panels: vec![Panel {
                title: "IMU–GNSS time offset (GNSS time tag − true validity)".into(),
                y_label: "time offset (ms)".into(),
                lines,
                bands: vec![Band {
                    name: "±3σ".into(),
                    color: BLUE,
                    pts: rows
                        .iter()
                        .step_by(k)
                        .map(|r| {
                            (
                                rel_s(r[0], t0),
                                (r[1] - 3.0 * r[2]) * 1e3,
                                (r[1] + 3.0 * r[2]) * 1e3,
                            )
                        })
                        .collect(),
                }],
                dots: Vec::new(),
                y_range: Some(((lo - pad) * 1e3, (hi + pad) * 1e3)),
            }],
            width: WIDTH,
            panel_height: 300,
        })?;
        section(
            &mut html,
            "time-offset",
            "Time-offset state",
            "The y scale covers the converged estimate (σ within 3× its final value); the band is clipped at the edges before that.",
            &svg,
        );
    }

    if let Some(s) = &sync {
        let lock = s
            .lock_timeline
            .iter()
            .map(|l| {
                (
                    rel_s(l.start.sow, t0),
                    rel_s(l.end.sow, t0),
                    l.state.clone(),
                )
            })
            .collect();
        let holdover = s
            .holdover
            .iter()
            .map(|h| (rel_s(h.start.sow, t0), rel_s(h.end.sow, t0), h.max_bound_us))
            .collect();
        let rejected = s
            .rejected_pulses
            .iter()
            .map(|p| (rel_s(p.time.sow, t0), p.reason.clone()))
            .collect();
        let svg = plot::timeline(
            &Timeline {
                x_range: (0.0, x1),
                lock,
                holdover,
                rejected,
                outages: outage_spans.clone(),
            },
            WIDTH,
            300,
        )?;
        section(
            &mut html,
            "sync",
            "Synchronization timeline",
            "From sync_report.json: clock lock states, holdover spans (stamps made without a pulse within 1.5 s) with their largest error bound, 1PPS pulses rejected after lock, and GNSS outages for reference.",
            &svg,
        );
        if let Some(h) = &s.gnss.latency_histogram_ms {
            let svg = plot::histogram(
                "GNSS message latency",
                "latency from validity to the message's last byte (ms)",
                h.start,
                h.width,
                &h.counts,
                (WIDTH, 300),
            )?;
            section(
                &mut html,
                "latency",
                "GNSS latency",
                &format!(
                    "{} fixes in bins of {} ms (measured by the logger's counter against 1PPS-derived GPS time).",
                    s.gnss.stamped, h.width
                ),
                &svg,
            );
        }
    }

    sections::gaps_section(
        &mut html,
        &gaps,
        median_fix_interval_s,
        sync.as_ref(),
        summary.as_ref(),
    );
    sections::drift_section(
        &mut html,
        &gaps,
        forward_std_full.is_some(),
        !sigma_h.is_empty(),
    );

    // The scores and the verdict as data, for tools and tests.
    let json_err = |e: serde_json::Error| Error::Invalid(e.to_string());
    if let Some(eval) = &eval {
        let json = serde_json::to_string(eval).map_err(json_err)?;
        let _ = writeln!(
            html,
            "<script type=\"application/json\" id=\"navsync-eval\">{json}</script>"
        );
    }
    let json = serde_json::to_string(&verdict).map_err(json_err)?;
    let _ = write!(
        html,
        "<script type=\"application/json\" id=\"navsync-verdict\">{json}</script>\n</body></html>\n"
    );
    Ok(Report {
        html,
        eval,
        verdict,
        diagnostics: diag,
    })
}

/// The GNSS weighting section: NIS of every position fix against its χ²
/// bounds, the smallest axis weight, and a table of the fixes that were
/// not used at their stated σ.
fn gnss_weighting_section(
    html: &mut String,
    fixes: &[FixWeight],
    t0: f64,
    x1: f64,
    shades: &[Shade],
) -> Result<(), Error> {
    // χ²(3) quantiles: 95 % 7.815, 99.99 % 21.108.
    let q = |p: f64| quality::chi2_quantile(p, quality::POSITION_DOF).unwrap_or(f64::NAN);
    let (q95, q9999) = (q(0.95), q(0.9999));
    let pts = |f: &dyn Fn(&FixWeight) -> f64| -> Vec<(f64, f64)> {
        fixes.iter().map(|x| (rel_s(x.sow, t0), f(x))).collect()
    };
    let min_w = |x: &FixWeight| x.weight.iter().copied().fold(f64::INFINITY, f64::min);
    let svg = plot::time_series(&Figure {
        x_label: "time since the first epoch (s)".into(),
        x_range: (0.0, x1),
        shades: shades.to_vec(),
        panels: vec![
            Panel {
                title: "GNSS position NIS at the stated σ (log10, 3 degrees of freedom)".into(),
                y_label: "log10 NIS".into(),
                lines: vec![
                    Line {
                        name: "NIS".into(),
                        color: BLUE,
                        width: 1,
                        pts: pts(&|x| x.nis.max(1e-3).log10()),
                    },
                    Line {
                        name: "95 % bound".into(),
                        color: GREY,
                        width: 1,
                        pts: vec![(0.0, q95.log10()), (x1, q95.log10())],
                    },
                    Line {
                        name: "99.99 % bound".into(),
                        color: RED,
                        width: 1,
                        pts: vec![(0.0, q9999.log10()), (x1, q9999.log10())],
                    },
                ],
                bands: Vec::new(),
                dots: Vec::new(),
                y_range: None,
            },
            Panel {
                title: "smallest axis weight (1: used at its stated σ; 0: rejected)".into(),
                y_label: "weight".into(),
                lines: vec![Line {
                    name: "weight".into(),
                    color: ORANGE,
                    width: 1,
                    pts: pts(&min_w),
                }],
                bands: Vec::new(),
                dots: Vec::new(),
                y_range: Some((0.0, 1.05)),
            },
        ],
        width: WIDTH,
        panel_height: 200,
    })?;
    let n_down = fixes.iter().filter(|x| x.status != "used").count();
    let inside = fixes.iter().filter(|x| x.nis <= q95).count();
    let note = format!(
        "{} position fixes; {} ({:.1} %) within the 95 % NIS bound (95 % expected when the stated σ and the filter's covariance are right); {} not used at their stated σ (gnss_residuals.txt has every fix). Robust weighting (navsync fuse --gnss-weighting robust): IGG-III weights on the standardised innovation (Yang, Song & Xu, Journal of Geodesy 76, 2002), judged against the INS's measured spread. Shaded: GNSS outages, and the fault monitor's episodes (red: fixes excluded; purple: fixes followed again without the INS resolving the episode; table below).",
        fixes.len(),
        inside,
        100.0 * inside as f64 / fixes.len().max(1) as f64,
        n_down
    );
    section(html, "gnss-weighting", "GNSS weighting", &note, &svg);
    if n_down > 0 {
        html.push_str("<details><summary>Fixes not used at their stated σ</summary>\n<table class=\"metrics\"><tr><th>SOW</th><th>status</th><th>NIS</th><th>innovation N, E, D (m)</th><th>stated σ N, E, D (m)</th><th>weight N, E, D</th></tr>\n");
        for x in fixes.iter().filter(|x| x.status != "used").take(200) {
            let _ = writeln!(
                html,
                "<tr><td>{:.3}</td><td>{}</td><td>{:.1}</td><td>{:.3}, {:.3}, {:.3}</td><td>{:.3}, {:.3}, {:.3}</td><td>{:.3}, {:.3}, {:.3}</td></tr>",
                x.sow,
                escape(&x.status),
                x.nis,
                x.innovation[0],
                x.innovation[1],
                x.innovation[2],
                x.sd[0],
                x.sd[1],
                x.sd[2],
                x.weight[0],
                x.weight[1],
                x.weight[2]
            );
        }
        html.push_str("</table></details>\n");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_of_flags() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(
            spans_where(&t, &[true, true, false, true, true]),
            vec![(0.0, 1.0), (3.0, 4.0)]
        );
        assert!(spans_where(&t, &[false; 5]).is_empty());
        assert_eq!(escape("<a&\"b\">"), "&lt;a&amp;&quot;b&quot;&gt;");
    }
}
