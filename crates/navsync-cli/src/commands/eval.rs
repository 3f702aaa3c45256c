//! `navsync eval`: errors of a solution against a reference trajectory.

use std::path::PathBuf;

use anyhow::{Context, Result};
use navsync::Diagnostics;
use navsync::eval::{self, EvalReport};

use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scored: super::Scored,
    /// Also write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    let s = &args.scored;
    let outages = eval::parse_outages(&s.outages, 0)?;
    let mut diag = Diagnostics::default();
    let report = eval::eval_files(&s.truth, &s.nav, &outages, &mut diag)?;
    print!("{}", format_report(&report));
    if let Some(p) = &args.json {
        std::fs::write(p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if !diag.is_empty() {
        eprintln!("{} lines skipped:", diag.total);
        print_diagnostics(&diag, 10);
    }
    Ok(())
}

/// The report as a readable table.
pub fn format_report(r: &EvalReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "epochs compared: {} (without truth: {})",
        r.epochs_compared, r.epochs_without_truth
    );
    let _ = writeln!(
        s,
        "{:<22} {:>12} {:>12} {:>12}",
        "error", "RMS", "max", "mean"
    );
    for (name, unit, e) in r.rows() {
        let _ = writeln!(
            s,
            "{:<22} {:>12.4} {:>12.4} {:>12.4}",
            format!("{name} ({unit})"),
            e.rms,
            e.max,
            e.mean
        );
    }
    if !r.outages.is_empty() {
        let _ = writeln!(s, "GNSS outages ({}):", r.outages.len());
        for o in &r.outages {
            let _ = writeln!(
                s,
                "  {:>12.3} +{:>5.1} s: max horizontal drift {:>8.3} m, max 3D {:>8.3} m",
                o.start_sow, o.len_s, o.max_horizontal_m, o.max_3d_m
            );
        }
        if let (Some(h), Some(d), Some(wh)) = (
            r.outage_rms_max_horizontal_m,
            r.outage_rms_max_3d_m,
            r.outage_worst_horizontal_m,
        ) {
            let _ = writeln!(
                s,
                "  RMS of max drift per outage: horizontal {h:.3} m, 3D {d:.3} m (worst horizontal {wh:.3} m)"
            );
        }
    }
    s
}
