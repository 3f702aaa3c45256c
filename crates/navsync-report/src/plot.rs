//! The report's figures as SVG text (plotters' SVG backend, no fonts or
//! network needed: text is left to the browser).

use navsync::Error;
use plotters::coord::Shift;
use plotters::prelude::*;

/// A curve.
#[derive(Clone, Debug)]
pub(crate) struct Line {
    pub name: String,
    pub color: RGBColor,
    pub width: u32,
    pub pts: Vec<(f64, f64)>,
}

/// A filled band between `lo` and `hi`: (x, lo, hi).
#[derive(Clone, Debug)]
pub(crate) struct Band {
    pub name: String,
    pub color: RGBColor,
    pub pts: Vec<(f64, f64, f64)>,
}

/// Shaded x intervals (GNSS outages, held estimates).
#[derive(Clone, Debug)]
pub(crate) struct Shade {
    pub name: String,
    pub color: RGBColor,
    pub spans: Vec<(f64, f64)>,
}

/// One chart of a stacked figure.
#[derive(Clone, Debug, Default)]
pub(crate) struct Panel {
    pub title: String,
    pub y_label: String,
    pub lines: Vec<Line>,
    pub bands: Vec<Band>,
    /// Points drawn as dots (not joined), outside the automatic y range:
    /// those beyond it are drawn at its edge.
    pub dots: Vec<Line>,
    /// Fixed y range; values outside are drawn at its edge.
    pub y_range: Option<(f64, f64)>,
}

/// Panels sharing an x axis, stacked.
#[derive(Clone, Debug)]
pub(crate) struct Figure {
    pub x_label: String,
    pub x_range: (f64, f64),
    pub shades: Vec<Shade>,
    pub panels: Vec<Panel>,
    pub width: u32,
    pub panel_height: u32,
}

pub(crate) const RED: RGBColor = RGBColor(200, 40, 40);
pub(crate) const GREEN: RGBColor = RGBColor(30, 140, 30);
pub(crate) const BLUE: RGBColor = RGBColor(30, 80, 200);
pub(crate) const GREY: RGBColor = RGBColor(120, 120, 120);
pub(crate) const ORANGE: RGBColor = RGBColor(230, 120, 0);
/// Shading of GNSS outages.
pub(crate) const OUTAGE: RGBColor = RGBColor(235, 175, 30);
/// Shading of held estimates.
pub(crate) const PURPLE: RGBColor = RGBColor(140, 90, 210);
/// Colours of the x/y/z (north/east/down) components.
pub(crate) const AXES: [RGBColor; 3] = [RED, GREEN, BLUE];

const FONT: &str = "sans-serif";

fn pe<E: std::fmt::Display>(e: E) -> Error {
    Error::Invalid(format!("drawing a plot: {e}"))
}

/// Every `stride`-th index keeps at most `max` points of `n`.
pub(crate) fn stride(n: usize, max: usize) -> usize {
    n.div_ceil(max.max(1)).max(1)
}

/// Padded range of finite values; a flat or empty set gets ±1 (or ±10 %).
fn padded(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-12 * lo.abs().max(1e-12) {
        let d = if lo.abs() > 0.0 { 0.1 * lo.abs() } else { 1.0 };
        return (lo - d, hi + d);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// Width of the legend column right of every chart (px).
const LEGEND_W: u32 = 190;

/// How a legend entry is drawn.
#[derive(Copy, Clone, Debug)]
enum Swatch {
    Line(RGBColor, u32),
    Fill(RGBColor, f64),
    Marker(RGBColor),
    Dot(RGBColor),
}

/// Draws `entries` top-down in the legend column `area`.
fn side_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(String, Swatch)],
    top: i32,
) -> Result<(), Error> {
    let style = (FONT, 15).into_font().color(&BLACK);
    for (k, (name, sw)) in entries.iter().enumerate() {
        let y = top + 22 * k as i32;
        let (x0, x1) = (8, 30);
        match *sw {
            Swatch::Line(c, w) => area
                .draw(&PathElement::new(vec![(x0, y), (x1, y)], c.stroke_width(w)))
                .map_err(pe)?,
            Swatch::Fill(c, a) => area
                .draw(&Rectangle::new(
                    [(x0, y - 6), (x1, y + 6)],
                    c.mix(a).filled(),
                ))
                .map_err(pe)?,
            Swatch::Marker(c) => area
                .draw(&TriangleMarker::new((19, y), 6, c.filled()))
                .map_err(pe)?,
            Swatch::Dot(c) => area
                .draw(&Circle::new((19, y), 3, c.filled()))
                .map_err(pe)?,
        }
        area.draw(&Text::new(name.clone(), (x1 + 8, y - 7), style.clone()))
            .map_err(pe)?;
    }
    Ok(())
}

/// Decimals for tick labels over a range (about 5–10 ticks).
fn decimals(span: f64) -> usize {
    if !(span > 0.0 && span.is_finite()) {
        return 1;
    }
    (-(span / 8.0).log10().floor()).clamp(0.0, 6.0) as usize
}

/// Tick labels without "-0.0" and with as many decimals as the range needs.
pub(crate) fn tick(v: f64, dec: usize) -> String {
    let s = format!("{v:.dec$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Axes of a chart: caption, ranges, descriptions and label-area sizes.
struct Axes<'t> {
    caption: &'t str,
    x: (f64, f64),
    y: (f64, f64),
    x_desc: &'t str,
    y_desc: &'t str,
    /// Height of the x label area and width of the y label area (px).
    label_px: (u32, u32),
    /// Name the four rows of the timeline instead of numbering y.
    rows: bool,
}

type Chart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A chart in the report's style (fonts, light grid, tick labels).
fn chart_on<'a, DB: DrawingBackend + 'a>(
    area: &DrawingArea<DB, Shift>,
    a: &Axes,
) -> Result<Chart<'a, DB>, Error> {
    let mut chart = ChartBuilder::on(area)
        .caption(a.caption, (FONT, 17))
        .margin(8)
        .margin_right(12)
        .x_label_area_size(a.label_px.0)
        .y_label_area_size(a.label_px.1)
        .build_cartesian_2d(a.x.0..a.x.1, a.y.0..a.y.1)
        .map_err(pe)?;
    let (xd, yd) = (decimals(a.x.1 - a.x.0), decimals(a.y.1 - a.y.0));
    let row_name = |v: &f64| {
        let r = v - v.floor();
        if (r - 0.5).abs() < 1e-6 && *v >= 0.0 && *v < 4.0 {
            ROWS[v.floor() as usize].to_string()
        } else {
            String::new()
        }
    };
    let number = |v: &f64| tick(*v, yd);
    let x_number = |v: &f64| tick(*v, xd);
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(a.x_desc)
        .y_desc(a.y_desc)
        .x_label_formatter(&x_number)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(BLACK.mix(0.05))
        .bold_line_style(BLACK.mix(0.12));
    if a.rows {
        mesh.disable_y_mesh()
            .y_labels(9)
            .y_label_formatter(&row_name);
    } else {
        mesh.y_label_formatter(&number);
    }
    mesh.draw().map_err(pe)?;
    Ok(chart)
}

/// Stacked time series with bands and shaded intervals.
pub(crate) fn time_series(fig: &Figure) -> Result<String, Error> {
    let mut svg = String::new();
    {
        let h = fig.panel_height * fig.panels.len().max(1) as u32;
        let root = SVGBackend::with_string(&mut svg, (fig.width, h)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let areas = root.split_evenly((fig.panels.len().max(1), 1));
        for (k, (panel, area)) in fig.panels.iter().zip(areas.iter()).enumerate() {
            draw_panel(fig, panel, area, k == 0, k + 1 == fig.panels.len())?;
        }
        root.present().map_err(pe)?;
    }
    Ok(svg)
}

fn draw_panel<DB: DrawingBackend>(
    fig: &Figure,
    p: &Panel,
    area: &DrawingArea<DB, Shift>,
    first: bool,
    last: bool,
) -> Result<(), Error> {
    let (x0, x1) = fig.x_range;
    let (y0, y1) = p.y_range.unwrap_or_else(|| {
        padded(
            p.lines
                .iter()
                .flat_map(|l| l.pts.iter().map(|q| q.1))
                .chain(
                    p.bands
                        .iter()
                        .flat_map(|b| b.pts.iter().flat_map(|q| [q.1, q.2])),
                ),
        )
    });
    // plotters' mesh never ends on an infinite range (`report
    // --time-offset-truth inf` looped): refuse it.
    if !(x0.is_finite() && x1.is_finite() && y0.is_finite() && y1.is_finite()) || x0 > x1 || y0 > y1
    {
        return Err(Error::Invalid(format!(
            "plot '{}': axis range x {x0}…{x1}, y {y0}…{y1} is not finite",
            p.title
        )));
    }
    let clamp = |y: f64| y.clamp(y0, y1);
    let (plot_area, legend_area) = area.split_horizontally(fig.width.saturating_sub(LEGEND_W));
    let mut chart = chart_on(
        &plot_area,
        &Axes {
            caption: &p.title,
            x: (x0, x1),
            y: (y0, y1),
            x_desc: if last { fig.x_label.as_str() } else { "" },
            y_desc: &p.y_label,
            label_px: (if last { 40 } else { 25 }, 70),
            rows: false,
        },
    )?;
    let mut legend = Vec::new();
    for s in &fig.shades {
        let color = s.color;
        chart
            .draw_series(s.spans.iter().map(|&(a, b)| {
                Rectangle::new([(a.max(x0), y0), (b.min(x1), y1)], color.mix(0.2).filled())
            }))
            .map_err(pe)?;
        if first && !s.spans.is_empty() {
            legend.push((s.name.clone(), Swatch::Fill(color, 0.3)));
        }
    }
    for b in &p.bands {
        let color = b.color;
        let mut poly: Vec<(f64, f64)> = b.pts.iter().map(|q| (q.0, clamp(q.2))).collect();
        poly.extend(b.pts.iter().rev().map(|q| (q.0, clamp(q.1))));
        chart
            .draw_series(std::iter::once(Polygon::new(poly, color.mix(0.3).filled())))
            .map_err(pe)?;
        legend.push((b.name.clone(), Swatch::Fill(color, 0.4)));
    }
    for l in &p.lines {
        chart
            .draw_series(LineSeries::new(
                l.pts.iter().map(|&(x, y)| (x, clamp(y))),
                l.color.stroke_width(l.width),
            ))
            .map_err(pe)?;
        if !l.name.is_empty() {
            legend.push((l.name.clone(), Swatch::Line(l.color, l.width.max(2))));
        }
    }
    for d in &p.dots {
        let (color, r) = (d.color, d.width.max(1));
        chart
            .draw_series(
                d.pts
                    .iter()
                    .map(|&(x, y)| Circle::new((x, clamp(y)), r, color.filled())),
            )
            .map_err(pe)?;
        if !d.name.is_empty() && !d.pts.is_empty() {
            legend.push((d.name.clone(), Swatch::Dot(color)));
        }
    }
    side_legend(&legend_area, &legend, 40)
}

/// The horizontal trajectory (points as (north, east) in m), GNSS fixes and
/// the parts inside GNSS outages, at equal scales.
pub(crate) struct Trajectory<'a> {
    pub truth: &'a [(f64, f64)],
    pub solution: &'a [(f64, f64)],
    pub gnss: &'a [(f64, f64)],
    pub truth_in_outage: Vec<Vec<(f64, f64)>>,
    pub solution_in_outage: Vec<Vec<(f64, f64)>>,
}

pub(crate) fn trajectory(t: &Trajectory, width: u32, height: u32) -> Result<String, Error> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (plot_area, legend_area) = root.split_horizontally(width.saturating_sub(LEGEND_W));
        let (e0, e1) = padded(t.truth.iter().chain(t.solution).map(|p| p.1));
        let (n0, n1) = padded(t.truth.iter().chain(t.solution).map(|p| p.0));
        // Equal metres per pixel on both axes (the plotting area is about
        // the figure less the label areas and margins).
        let pw = f64::from(width.saturating_sub(LEGEND_W)) - 100.0;
        let ph = f64::from(height) - 90.0;
        let scale = ((e1 - e0) / pw).max((n1 - n0) / ph);
        let (ec, nc) = (0.5 * (e0 + e1), 0.5 * (n0 + n1));
        let (e0, e1) = (ec - 0.5 * scale * pw, ec + 0.5 * scale * pw);
        let (n0, n1) = (nc - 0.5 * scale * ph, nc + 0.5 * scale * ph);
        let mut chart = chart_on(
            &plot_area,
            &Axes {
                caption: "Trajectory (horizontal)",
                x: (e0, e1),
                y: (n0, n1),
                x_desc: "east of the start (m)",
                y_desc: "north of the start (m)",
                label_px: (40, 70),
                rows: false,
            },
        )?;
        let en = |v: &[(f64, f64)]| v.iter().map(|p| (p.1, p.0)).collect::<Vec<_>>();
        let truth_c = RGBColor(60, 60, 60);
        let mut legend = Vec::new();
        if !t.truth.is_empty() {
            legend.push(("truth".to_string(), Swatch::Line(truth_c, 3)));
        }
        legend.push(("solution".to_string(), Swatch::Line(BLUE, 2)));
        chart
            .draw_series(LineSeries::new(en(t.truth), truth_c.stroke_width(3)))
            .map_err(pe)?;
        for seg in &t.truth_in_outage {
            chart
                .draw_series(LineSeries::new(en(seg), OUTAGE.stroke_width(7)))
                .map_err(pe)?;
        }
        chart
            .draw_series(LineSeries::new(en(t.solution), BLUE.stroke_width(1)))
            .map_err(pe)?;
        for seg in &t.solution_in_outage {
            chart
                .draw_series(LineSeries::new(en(seg), RED.stroke_width(2)))
                .map_err(pe)?;
        }
        if !t.gnss.is_empty() {
            chart
                .draw_series(
                    en(t.gnss)
                        .into_iter()
                        .map(|p| Circle::new(p, 2, GREEN.filled())),
                )
                .map_err(pe)?;
            legend.push(("GNSS fix".to_string(), Swatch::Dot(GREEN)));
        }
        if !t.truth_in_outage.is_empty() {
            legend.push(("truth in GNSS outage".to_string(), Swatch::Line(OUTAGE, 7)));
            legend.push(("solution in outage".to_string(), Swatch::Line(RED, 2)));
        }
        side_legend(&legend_area, &legend, 40)?;
        root.present().map_err(pe)?;
    }
    Ok(svg)
}

/// The synchronization timeline: clock lock states, holdover spans,
/// rejected pulses and GNSS outages on rows over time.
pub(crate) struct Timeline {
    pub x_range: (f64, f64),
    /// (start, end, state) with state acquiring, locked, holdover or software.
    pub lock: Vec<(f64, f64, String)>,
    /// (start, end, largest stamp-error bound µs).
    pub holdover: Vec<(f64, f64, f64)>,
    /// (time, reason).
    pub rejected: Vec<(f64, String)>,
    pub outages: Vec<(f64, f64)>,
}

const ROWS: [&str; 4] = ["GNSS outage", "rejected 1PPS", "holdover", "clock lock"];

fn state_color(state: &str) -> RGBColor {
    match state {
        "locked" => GREEN,
        "holdover" => ORANGE,
        "software" => BLUE,
        _ => GREY,
    }
}

pub(crate) fn timeline(t: &Timeline, width: u32, height: u32) -> Result<String, Error> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (plot_area, legend_area) = root.split_horizontally(width.saturating_sub(LEGEND_W));
        let (x0, x1) = t.x_range;
        let mut chart = chart_on(
            &plot_area,
            &Axes {
                caption: "Synchronization timeline",
                x: (x0, x1),
                y: (0.0, 4.0),
                x_desc: "time since the first epoch (s)",
                y_desc: "",
                label_px: (40, 110),
                rows: true,
            },
        )?;
        let row = |i: f64| (i + 0.2, i + 0.8);
        let mut legend: Vec<(String, Swatch)> = Vec::new();
        let (lo, hi) = row(3.0);
        for (a, b, s) in &t.lock {
            let c = state_color(s);
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(*a, lo), (*b, hi)],
                    c.mix(0.75).filled(),
                )))
                .map_err(pe)?;
            let name = format!("clock {s}");
            if !legend.iter().any(|(n, _)| *n == name) {
                legend.push((name, Swatch::Fill(c, 0.75)));
            }
        }
        let (lo, hi) = row(2.0);
        let span = (x1 - x0).max(1e-9);
        let label = (FONT, 14).into_font().color(&BLACK);
        for (a, b, bound) in &t.holdover {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(*a, lo), ((*b).max(a + 0.002 * span), hi)],
                    ORANGE.mix(0.6).filled(),
                )))
                .map_err(pe)?;
            // Spans longer than 2 % of the run get their figures beside them.
            if (b - a) / span > 0.02 {
                chart
                    .draw_series(std::iter::once(Text::new(
                        format!("{:.0} s, bound ≤ {:.1} µs", b - a, bound),
                        (b + 0.01 * span, 0.5 * (lo + hi) + 0.12),
                        label.clone(),
                    )))
                    .map_err(pe)?;
            }
        }
        if !t.holdover.is_empty() {
            legend.push(("holdover span".into(), Swatch::Fill(ORANGE, 0.6)));
        }
        let (lo, hi) = row(1.0);
        if !t.rejected.is_empty() {
            chart
                .draw_series(t.rejected.iter().map(|(x, reason)| {
                    let c = if reason == "spurious" { RED } else { BLUE };
                    TriangleMarker::new((*x, 0.5 * (lo + hi)), 6, c.filled())
                }))
                .map_err(pe)?;
            legend.push(("spurious pulse".into(), Swatch::Marker(RED)));
            legend.push(("displaced/duplicate".into(), Swatch::Marker(BLUE)));
        }
        let (lo, hi) = row(0.0);
        for (a, b) in &t.outages {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(*a, lo), (*b, hi)],
                    OUTAGE.mix(0.5).filled(),
                )))
                .map_err(pe)?;
        }
        if !t.outages.is_empty() {
            legend.push(("GNSS outage".into(), Swatch::Fill(OUTAGE, 0.5)));
        }
        side_legend(&legend_area, &legend, 40)?;
        root.present().map_err(pe)?;
    }
    Ok(svg)
}

/// Bars of a histogram (`start`, bin `width`, counts).
pub(crate) fn histogram(
    title: &str,
    x_label: &str,
    start: f64,
    width_bin: f64,
    counts: &[u64],
    size: (u32, u32),
) -> Result<String, Error> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let x1 = start + width_bin * counts.len().max(1) as f64;
        let top = counts.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
        let mut chart = chart_on(
            &root,
            &Axes {
                caption: title,
                x: (start, x1),
                y: (0.0, top),
                x_desc: x_label,
                y_desc: "count",
                label_px: (40, 60),
                rows: false,
            },
        )?;
        chart
            .draw_series(counts.iter().enumerate().map(|(i, &c)| {
                let a = start + i as f64 * width_bin;
                Rectangle::new(
                    [(a, 0.0), (a + width_bin, c as f64)],
                    BLUE.mix(0.6).filled(),
                )
            }))
            .map_err(pe)?;
        root.present().map_err(pe)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_and_strides() {
        assert_eq!(stride(120_000, 1000), 120);
        assert_eq!(stride(10, 1000), 1);
        assert_eq!(padded([1.0, 3.0].into_iter()), (0.9, 3.1));
        assert_eq!(padded([f64::NAN].into_iter()), (-1.0, 1.0));
        assert_eq!(padded([2.0, 2.0].into_iter()), (1.8, 2.2));
        assert_eq!((decimals(600.0), decimals(0.5), decimals(6.0)), (0, 2, 1));
        assert_eq!(tick(-1e-17, 1), "0.0");
        assert_eq!(tick(-0.25, 2), "-0.25");
    }

    #[test]
    fn a_figure_is_one_svg_element_with_its_labels() {
        let fig = Figure {
            x_label: "time (s)".into(),
            x_range: (0.0, 10.0),
            shades: vec![Shade {
                name: "GNSS outage".into(),
                color: GREY,
                spans: vec![(2.0, 4.0)],
            }],
            panels: vec![Panel {
                title: "north".into(),
                y_label: "error (m)".into(),
                lines: vec![Line {
                    name: "error".into(),
                    color: RED,
                    width: 1,
                    pts: (0..10).map(|i| (i as f64, (i as f64).sin())).collect(),
                }],
                bands: vec![Band {
                    name: "±3σ".into(),
                    color: GREY,
                    pts: (0..10).map(|i| (i as f64, -2.0, 2.0)).collect(),
                }],
                dots: Vec::new(),
                y_range: None,
            }],
            width: 600,
            panel_height: 200,
        };
        let svg = time_series(&fig).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..40]);
        assert_eq!(svg.matches("<svg").count(), 1);
        for label in [
            "time (s)",
            "error (m)",
            "GNSS outage",
            "±3σ",
            "north",
            "\nerror\n",
        ] {
            assert!(svg.contains(label), "missing {label}");
        }
    }
}
