//! `navsync export`: a navigation solution (11-column nav format) to GPX,
//! KML, GeoJSON, CSV or TUM, with the σ of a `std.txt` beside it (the
//! formatting is in `navsync::io::export`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use navsync::Diagnostics;
use navsync::io::export::{self, ExportFormat, ExportMeta, ExportPoint};
use navsync::io::kfgins::NavReader;
use navsync_receivers::geoid::{EGM96_SOURCE, Egm96Grid};
use navsync_receivers::gnsstime::gps_to_unix_ns;

use super::args;
use super::print_diagnostics;

#[derive(Copy, Clone, Debug, clap::ValueEnum)]
pub enum To {
    /// GPX 1.1 track: MSL height (EGM96), UTC time, position σ as extension elements.
    Gpx,
    /// KML 2.2: track line and time-stamped points with σ (Google Earth).
    Kml,
    /// GeoJSON (RFC 7946): track line and points with every value and σ as properties.
    Geojson,
    /// CSV with a header naming units (pandas).
    Csv,
    /// TUM trajectory for evo: `timestamp tx ty tz qx qy qz qw`, NED at the first epoch.
    Tum,
}

#[derive(clap::Args)]
pub struct Args {
    /// Navigation solution (11-column nav format, e.g. navresult.nav).
    pub nav: PathBuf,
    /// Output format.
    #[arg(long, value_enum)]
    pub to: To,
    /// Keep one epoch per this many seconds of GPS time (the first of each
    /// interval: whole seconds for 1); 0 keeps every epoch.
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub every: f64,
    /// Output file (default: NAV with the format's extension).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// KF-GINS std.txt with the solution's σ (default: std.txt beside NAV when present).
    #[arg(long)]
    pub std: Option<PathBuf>,
    /// Export without σ even when std.txt is beside NAV.
    #[arg(long, conflicts_with = "std")]
    pub no_std: bool,
}

pub fn run(a: Args) -> Result<()> {
    let format = match a.to {
        To::Gpx => ExportFormat::Gpx,
        To::Kml => ExportFormat::Kml,
        To::Geojson => ExportFormat::GeoJson,
        To::Csv => ExportFormat::Csv,
        To::Tum => ExportFormat::Tum,
    };
    let mut diag = Diagnostics::default();
    let mut recs = NavReader::read_all(&a.nav, &mut diag)?;
    let read = recs.len();
    recs.retain(|r| match export::off_earth(r) {
        Some(why) => {
            diag.push(&a.nav, 0, format!("epoch {}: {why}; not exported", r.time));
            false
        }
        None => true,
    });
    if read > 0 && recs.is_empty() {
        bail!(
            "{}: no epoch with a position on the earth to export",
            a.nav.display()
        );
    }
    let recs = export::decimate(&recs, a.every);
    let week = recs.first().map_or(0, |r| r.week);
    let std_path = match (&a.std, a.no_std) {
        (Some(p), _) => Some(p.clone()),
        (None, true) => None,
        (None, false) => {
            let p = a.nav.with_file_name("std.txt");
            p.is_file().then_some(p)
        }
    };
    let sd = match &std_path {
        Some(p) => export::read_std(p, week, &mut diag)?,
        None => Vec::new(),
    };
    let needs_geoid = matches!(format, ExportFormat::Gpx | ExportFormat::Kml);
    let mut geoid = Egm96Grid::new();
    let points: Vec<ExportPoint> = recs
        .iter()
        .map(|r| ExportPoint {
            rec: *r,
            sd: export::sd_at(&sd, r.time),
            geoid_m: if needs_geoid {
                geoid.separation_m(r.lat_deg, r.lon_deg)
            } else {
                None
            },
            // A week of 0 means "unknown" (KF-GINS): no calendar time.
            utc_unix_ns: (r.week > 0).then(|| gps_to_unix_ns(r.time)),
        })
        .collect();
    let output = a
        .output
        .clone()
        .unwrap_or_else(|| a.nav.with_extension(format.extension()));
    let mut inputs = vec![a.nav.as_path()];
    inputs.extend(std_path.as_deref());
    args::refuse_output_over_input(&output, &inputs, "--output")?;
    let meta = ExportMeta {
        name: a
            .nav
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        creator: format!("navsync {}", env!("CARGO_PKG_VERSION")),
    };
    let mut out = Vec::with_capacity(points.len() * 200);
    export::write(format, &points, &meta, &mut out);
    navsync::io::output::write_file(&output, &out)
        .with_context(|| format!("writing {}", output.display()))?;
    let with_sd = points.iter().filter(|p| p.sd.is_some()).count();
    println!(
        "{}: {} epochs ({} with σ from {}) → {}",
        a.nav.display(),
        points.len(),
        with_sd,
        std_path
            .as_ref()
            .map_or("no std.txt".into(), |p| p.display().to_string()),
        output.display()
    );
    if needs_geoid {
        println!("  heights above mean sea level from the {EGM96_SOURCE}");
    }
    if week == 0 && matches!(format, ExportFormat::Gpx | ExportFormat::Kml) {
        eprintln!("navsync: note: the nav file has week 0 (unknown): no UTC times written");
    }
    if matches!(format, ExportFormat::Gpx | ExportFormat::Kml) && points.len() > 100_000 {
        eprintln!(
            "navsync: note: {} points; viewers are slow past ~100 000: see --every",
            points.len()
        );
    }
    if !diag.is_empty() {
        eprintln!("{} lines skipped:", diag.total);
        print_diagnostics(&diag, 10);
    }
    Ok(())
}
