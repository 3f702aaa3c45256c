//! `navsync faults`: GNSS receiver faults injected into any KF-GINS GNSS
//! file, with labels (the core is `navsync_sim::faults`; issue 33).

use std::path::PathBuf;

use anyhow::{Context, Result};
use navsync_sim::faults::{self, FaultClass, FaultOptions, FaultRanges};

use super::{args, print_diagnostics};

#[derive(clap::Args)]
pub struct Args {
    /// The GNSS file (KF-GINS, 7 or 13 columns; positions are columns 2–4
    /// in both 13-column orders).
    #[arg(long)]
    pub gnss: PathBuf,
    /// Output folder: gnss.txt (with faults), faults.txt (one label per
    /// faulty fix), faults.json (every parameter and episode).
    #[arg(long)]
    pub output: PathBuf,
    #[arg(value_parser = args::seed(), long, default_value_t = 1)]
    pub seed: u64,
    /// Fault classes, cycled over the episodes: spike (one fix 15–50 m
    /// off), false-fix (a wrong RTK fix: constant 0.5–10 m for 8–15 s, σ
    /// unchanged), ramp (growing to 1–2 m over 15–25 s), stale (the last
    /// good line repeated with new times for 3–10 s).
    #[arg(long, value_parser = FaultClass::parse, value_delimiter = ',', default_value = "spike,false-fix,ramp,stale")]
    pub classes: Vec<FaultClass>,
    /// Number of episodes, placed at random (not in the first
    /// --skip-start seconds, --separation apart, not across gaps).
    #[arg(value_parser = args::count(1, 10_000), long, default_value_t = 4, conflicts_with = "plan")]
    pub count: usize,
    /// Explicit episodes instead: one a line, `class start_sow duration_s
    /// [offset_n_m offset_e_m offset_d_m]` (drawn when absent; a ramp's
    /// offset is its peak; stale takes none).
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Spike size range LO,HI (m, 3D).
    #[arg(long, value_parser = range_m, value_name = "LO,HI", default_value = "15,50")]
    pub spike_m: [f64; 2],
    /// False-fix offset range LO,HI (m, 3D).
    #[arg(long, value_parser = range_m, value_name = "LO,HI", default_value = "0.5,10")]
    pub false_fix_m: [f64; 2],
    /// False-fix duration range LO,HI (s).
    #[arg(long, value_parser = range_s, value_name = "LO,HI", default_value = "8,15")]
    pub false_fix_s: [f64; 2],
    /// Ramp peak range LO,HI (m, 3D).
    #[arg(long, value_parser = range_m, value_name = "LO,HI", default_value = "1,2")]
    pub ramp_m: [f64; 2],
    /// Ramp duration range LO,HI (s).
    #[arg(long, value_parser = range_s, value_name = "LO,HI", default_value = "15,25")]
    pub ramp_s: [f64; 2],
    /// Stale repeat duration range LO,HI (s).
    #[arg(long, value_parser = range_s, value_name = "LO,HI", default_value = "3,10")]
    pub stale_s: [f64; 2],
    /// Offsets' elevation drawn uniform within ± this (deg).
    #[arg(value_parser = args::non_negative(90.0, "deg"), long, default_value_t = 30.0)]
    pub max_elevation: f64,
    /// No episode starts within this of the first fix (s).
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long, default_value_t = 60.0)]
    pub skip_start: f64,
    /// Clean time between episodes (s).
    #[arg(value_parser = args::non_negative(3600.0, "s"), long, default_value_t = 20.0)]
    pub separation: f64,
}

/// "LO,HI" with 0 ≤ LO ≤ HI ≤ `hi`.
fn range(s: &str, hi: f64, unit: &'static str) -> Result<[f64; 2], String> {
    let r = args::non_negative(hi, unit);
    let v = s
        .split(',')
        .map(|x| r.check(x).map_err(|why| format!("'{}' is {why}", x.trim())))
        .collect::<Result<Vec<f64>, String>>()?;
    match v.as_slice() {
        [a, b] if a <= b => Ok([*a, *b]),
        [a, b] => Err(format!("'{s}': LO {a} above HI {b}")),
        _ => Err(format!("'{s}': expected LO,HI")),
    }
}

fn range_m(s: &str) -> Result<[f64; 2], String> {
    range(s, 1e4, "m")
}

fn range_s(s: &str) -> Result<[f64; 2], String> {
    range(s, 3600.0, "s")
}

pub fn run(a: Args) -> Result<()> {
    let out_gnss = a.output.join("gnss.txt");
    // Before the folder is taken (which moves an earlier run's files aside).
    for name in ["gnss.txt", "faults.txt", "faults.json"] {
        let mut inputs = vec![a.gnss.as_path()];
        inputs.extend(a.plan.as_deref());
        args::refuse_output_over_input(&a.output.join(name), &inputs, "--output")?;
    }
    let _held = super::take_output(&a.output, "faults")?;
    let plan = match &a.plan {
        Some(p) => Some(faults::read_plan(p)?),
        None => None,
    };
    let o = FaultOptions {
        seed: a.seed,
        classes: a.classes,
        count: a.count,
        ranges: FaultRanges {
            spike_m: a.spike_m,
            false_fix_m: a.false_fix_m,
            false_fix_s: a.false_fix_s,
            ramp_m: a.ramp_m,
            ramp_s: a.ramp_s,
            stale_s: a.stale_s,
            max_elevation_deg: a.max_elevation,
        },
        skip_start_s: a.skip_start,
        min_separation_s: a.separation,
        plan,
    };
    let inj = faults::inject(&a.gnss, &o)?;
    faults::write_outputs(&a.output, &a.gnss, &o, &inj)
        .with_context(|| format!("writing {}", a.output.display()))?;
    println!(
        "navsync faults: {} episodes, {} of {} fixes faulty → {} (labels faults.txt, parameters faults.json)",
        inj.episodes.len(),
        inj.labels.len(),
        inj.fixes,
        out_gnss.display()
    );
    for e in &inj.episodes {
        let [n, east, d] = e.offset_ned_m;
        println!(
            "  {:>2} {:<9} {:.1}–{:.1} s ({} fix{}), offset N/E/D {n:+.2} {east:+.2} {d:+.2} m",
            e.episode,
            e.class.name(),
            e.first_sow,
            e.last_sow,
            e.fixes,
            if e.fixes == 1 { "" } else { "es" }
        );
    }
    if !inj.diagnostics.is_empty() {
        eprintln!(
            "{} lines of {} copied unchanged (not read as fixes):",
            inj.diagnostics.total,
            a.gnss.display()
        );
        print_diagnostics(&inj.diagnostics, 10);
    }
    Ok(())
}
