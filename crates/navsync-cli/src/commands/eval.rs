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
    if let Some(p) = &args.json {
        super::args::refuse_output_over_input(p, &[&s.truth, &s.nav], "--json")?;
    }
    let outages = eval::parse_outages(&s.outages, 0)?;
    let mut diag = Diagnostics::default();
    let report = eval::eval_files(&s.truth, &s.nav, &outages, &mut diag)?;
    print!("{}", format_report(&report));
    // A smoothed run (`fuse --smooth`) keeps its forward solution in
    // forward/ beside it: score that too, side by side.
    let forward_nav = s
        .nav
        .parent()
        .map(|d| d.join("forward").join("navresult.nav"))
        .filter(|p| p.is_file());
    let forward = match &forward_nav {
        Some(p) => {
            let f = eval::eval_files(&s.truth, p, &outages, &mut diag)?;
            println!("\nforward filter ({}) against this solution:", p.display());
            print!("{}", format_comparison(&f, &report));
            Some(f)
        }
        None => None,
    };
    if let Some(p) = &args.json {
        let mut json = serde_json::to_value(&report)?;
        if let (Some(f), Some(obj)) = (&forward, json.as_object_mut()) {
            obj.insert("forward".into(), serde_json::to_value(f)?);
        }
        navsync::io::output::write_file(p, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if !diag.is_empty() {
        eprintln!("{} lines skipped:", diag.total);
        print_diagnostics(&diag, 10);
    }
    Ok(())
}

/// RMS of each error of `forward` and `smoothed` side by side, with the
/// ratio, and the outage drift of both.
pub fn format_comparison(forward: &EvalReport, smoothed: &EvalReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<26} {:>12} {:>12} {:>8}",
        "RMS error", "forward", "this", "ratio"
    );
    for ((name, unit, f), (_, _, m)) in forward.rows().into_iter().zip(smoothed.rows()) {
        let _ = writeln!(
            s,
            "{:<26} {:>12.4} {:>12.4} {:>8.3}",
            format!("{name} ({unit})"),
            f.rms,
            m.rms,
            m.rms / f.rms
        );
    }
    if let (Some(f), Some(m)) = (
        forward.outage_rms_max_horizontal_m,
        smoothed.outage_rms_max_horizontal_m,
    ) {
        let _ = writeln!(
            s,
            "{:<26} {:>12.4} {:>12.4} {:>8.3}",
            "outage drift, horiz. (m)",
            f,
            m,
            m / f
        );
    }
    s
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
