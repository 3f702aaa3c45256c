//! The carrier-tracking sweep's figure (`navsync track --svg`): phase
//! error against C/N0.

use std::path::Path;

use navsync::Error;

/// One C/N0 of a tracking sweep, as plotted.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PhaseErrorPoint {
    pub cn0_dbhz: f64,
    /// Measured 3σ + |bias| of the phase error (deg).
    pub measured_3sigma_deg: f64,
    /// The error budget's 3σ + |bias| (deg).
    pub predicted_3sigma_deg: f64,
    /// Measured RMS phase error (deg).
    pub rms_deg: f64,
    /// RMS of the best fixed bandwidth at this C/N0, when searched (deg).
    pub best_fixed_rms_deg: Option<f64>,
}

/// One plotted quantity of a point.
type Metric = Box<dyn Fn(&PhaseErrorPoint) -> f64>;

/// Phase error against C/N0 (measured and predicted 3σ + |bias|, RMS, the
/// best fixed bandwidth's RMS) with the tracking threshold `limit_deg`, as
/// an SVG file.
pub fn phase_error_svg(
    path: &Path,
    title: &str,
    results: &[PhaseErrorPoint],
    limit_deg: f64,
) -> Result<(), Error> {
    let err = |e: &dyn std::fmt::Display| Error::Invalid(format!("{}: {e}", path.display()));
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (900, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let x0 = results
        .iter()
        .map(|r| r.cn0_dbhz)
        .fold(f64::INFINITY, f64::min);
    let x1 = results
        .iter()
        .map(|r| r.cn0_dbhz)
        .fold(f64::NEG_INFINITY, f64::max)
        .max(x0 + 1.0);
    let y1 = 2.0 * limit_deg;
    let clip = |v: f64| if v.is_finite() { v.min(y1) } else { y1 };
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(x0..x1, 0.0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("C/N0 (dB-Hz)")
        .y_desc("phase error (deg)")
        .draw()
        .map_err(|e| err(&e))?;
    let series: [(&str, RGBColor, Metric); 3] = [
        (
            "measured 3σ+|bias|",
            RED,
            Box::new(|r| r.measured_3sigma_deg),
        ),
        (
            "predicted 3σ+|bias|",
            BLUE,
            Box::new(|r| r.predicted_3sigma_deg),
        ),
        ("measured RMS", BLACK, Box::new(|r| r.rms_deg)),
    ];
    for (name, color, f) in series {
        chart
            .draw_series(LineSeries::new(
                results.iter().map(|r| (r.cn0_dbhz, clip(f(r)))),
                color.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    if results.iter().any(|r| r.best_fixed_rms_deg.is_some()) {
        let green = RGBColor(0, 140, 0);
        chart
            .draw_series(LineSeries::new(
                results
                    .iter()
                    .filter_map(|r| r.best_fixed_rms_deg.map(|rms| (r.cn0_dbhz, clip(rms)))),
                green.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label("best fixed bandwidth RMS")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], green.stroke_width(2))
            });
    }
    chart
        .draw_series(LineSeries::new(
            [(x0, limit_deg), (x1, limit_deg)],
            BLACK.mix(0.4),
        ))
        .map_err(|e| err(&e))?
        .label(format!("rule-of-thumb limit {limit_deg}°"))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.4)));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
