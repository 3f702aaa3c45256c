//! Monte Carlo runs of the whole chain ([`crate::chain`]): one scenario,
//! N seeds (every random error source redrawn), in parallel; statistics of
//! the accuracy figures and the filter's consistency.
//!
//! Consistency is the average NEES over runs at each epoch k (Bar-Shalom,
//! Li & Kirubarajan 2001, "Estimation with Applications to Tracking and
//! Navigation", §5.4.2): ε_i,k = x̃ᵀ P⁻¹ x̃ for run i, ε̄_k = (1/N) Σ_i ε_i,k;
//! for a consistent filter N·ε̄_k is χ² with N·n degrees of freedom, so the
//! two-sided 95 % region of ε̄_k is [χ²_{Nn}(0.025), χ²_{Nn}(0.975)] / N.
//! It is evaluated for the position error (n = 3, x̃ from the truth, P the
//! filter's 3×3 position block) and for the time-offset state (n = 1).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::chain::{ChainDirs, ChainOptions, outage_windows, run_chain, true_time_offset_s};
use crate::{Scenario, Simulation};
use navsync::error::Error;
use navsync::eval::{EpochError, EvalReport, Evaluator, TruthScorer};
use navsync::fusion::TimeOffsetState;
use navsync::ins::{ImuErrors, NavState};
use navsync::pipeline::NavSink;
use navsync::stats::{chi2_quantile, quantile};
use navsync::time::GpsTime;

/// Settings of a Monte Carlo study.
#[derive(Clone, Debug)]
pub struct McOptions {
    pub runs: usize,
    /// Parallel runs (threads).
    pub jobs: usize,
    /// Seed of run 0; run i uses `first_seed + i`.
    pub first_seed: u64,
    /// Folder for the runs' files (each run's removed when it ends unless
    /// `keep_files`).
    pub work_dir: PathBuf,
    pub keep_files: bool,
    /// NEES epochs: the first auxiliary epoch in each step (s).
    pub nees_step_s: f64,
    /// NEES summaries leave out the first seconds (the filter's start-up,
    /// where the simulated initial state is exact but P₀ is not zero).
    pub nees_skip_s: f64,
    /// Score the RTS-smoothed solution instead of the forward one.
    pub smooth: bool,
}

impl Default for McOptions {
    fn default() -> Self {
        McOptions {
            runs: 50,
            jobs: 2,
            first_seed: 1,
            work_dir: std::env::temp_dir().join("navsync-montecarlo"),
            keep_files: false,
            nees_step_s: 1.0,
            nees_skip_s: 30.0,
            smooth: false,
        }
    }
}

/// One run's figures.
#[derive(Clone, Debug, Serialize)]
pub struct RunFigures {
    pub seed: u64,
    pub pos_horizontal_rms_m: f64,
    pub pos_3d_rms_m: f64,
    /// RMS over outages of the maximum horizontal drift in each (m).
    pub outage_rms_max_horizontal_m: Option<f64>,
    pub outage_worst_horizontal_m: Option<f64>,
    /// IMU stamps against their true times (µs).
    pub sync_rms_us: Option<f64>,
    pub sync_max_us: Option<f64>,
    /// Final time-offset estimate and its σ (s).
    pub time_offset_s: Option<f64>,
    pub time_offset_sd_s: Option<f64>,
    /// Final estimate − truth (s).
    pub time_offset_error_s: Option<f64>,
    pub gnss_fixes_rejected: usize,
    pub run_time_s: f64,
    #[serde(skip)]
    nees_pos: Vec<f64>,
    #[serde(skip)]
    nees_tau: Vec<f64>,
}

/// Mean and percentiles of one figure over the runs.
#[derive(Clone, Debug, Serialize)]
pub struct Distribution {
    pub name: String,
    pub unit: String,
    pub runs: usize,
    pub mean: f64,
    pub p50: f64,
    pub p95: f64,
    pub max: f64,
}

impl Distribution {
    fn of(name: &str, unit: &str, mut v: Vec<f64>) -> Distribution {
        v.retain(|x| x.is_finite());
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        Distribution {
            name: name.into(),
            unit: unit.into(),
            runs: v.len(),
            mean,
            p50: quantile(&mut v, 0.5),
            p95: quantile(&mut v, 0.95),
            max: quantile(&mut v, 1.0),
        }
    }
}

/// The average-NEES test of one state block.
#[derive(Clone, Debug, Serialize)]
pub struct NeesTest {
    pub state: String,
    pub dof: usize,
    /// Seconds between epochs, and the start-up left out of the summary.
    pub step_s: f64,
    pub skip_s: f64,
    /// 95 % region of the average NEES for N runs.
    pub lower: f64,
    pub upper: f64,
    /// Epochs tested (after the start-up) and the mean of ε̄_k over them.
    pub epochs: usize,
    pub mean_anees: f64,
    pub fraction_inside: f64,
    pub fraction_above: f64,
    pub fraction_below: f64,
    /// (s after the start, ε̄_k) at every epoch, start-up included.
    pub series: Vec<(f64, f64)>,
}

impl NeesTest {
    /// ε̄_k over the runs that have epoch k (all of them, normally), with
    /// the bounds for that many runs.
    fn of(state: &str, dof: usize, per_run: &[&[f64]], step_s: f64, skip_s: f64) -> NeesTest {
        let len = per_run.iter().map(|v| v.len()).max().unwrap_or(0);
        let runs = per_run.len().max(1);
        let bounds = |n: usize| {
            let k = (n * dof) as f64;
            (
                chi2_quantile(0.025, k) / n as f64,
                chi2_quantile(0.975, k) / n as f64,
            )
        };
        let (lower, upper) = bounds(runs);
        let mut series = Vec::new();
        let (mut inside, mut above, mut below, mut sum, mut tested) = (0, 0, 0, 0.0, 0);
        for k in 0..len {
            let vals: Vec<f64> = per_run
                .iter()
                .filter_map(|v| v.get(k).copied())
                .filter(|x| x.is_finite())
                .collect();
            if vals.is_empty() {
                continue;
            }
            let t = k as f64 * step_s;
            let a = vals.iter().sum::<f64>() / vals.len() as f64;
            series.push((t, a));
            if t < skip_s {
                continue;
            }
            let (lo, hi) = if vals.len() == runs {
                (lower, upper)
            } else {
                bounds(vals.len())
            };
            tested += 1;
            sum += a;
            if a < lo {
                below += 1;
            } else if a > hi {
                above += 1;
            } else {
                inside += 1;
            }
        }
        let frac = |c: usize| c as f64 / tested.max(1) as f64;
        NeesTest {
            state: state.into(),
            dof,
            step_s,
            skip_s,
            lower,
            upper,
            epochs: tested,
            mean_anees: sum / tested.max(1) as f64,
            fraction_inside: frac(inside),
            fraction_above: frac(above),
            fraction_below: frac(below),
            series,
        }
    }
}

/// Everything a study found (written as JSON).
#[derive(Clone, Debug, Serialize)]
pub struct McReport {
    pub tool: &'static str,
    pub version: &'static str,
    pub scenario: Scenario,
    pub runs: usize,
    pub jobs: usize,
    pub duration_s: f64,
    pub true_time_offset_s: Option<f64>,
    pub wall_time_s: f64,
    pub figures: Vec<Distribution>,
    pub nees_position: NeesTest,
    pub nees_time_offset: Option<NeesTest>,
    pub per_run: Vec<RunFigures>,
}

/// Scores a run in memory: the truth comparison of [`navsync::eval`] at every
/// epoch, and NEES at the first auxiliary epoch of every step.
struct McSink {
    /// Opened on the first epoch: the simulation stage writes the file.
    truth_path: PathBuf,
    scorer: Option<TruthScorer>,
    ev: Evaluator,
    last: Option<EpochError>,
    start: GpsTime,
    step_s: f64,
    next_k: usize,
    /// Epoch index waiting for its covariance.
    want: Option<usize>,
    tau_true: Option<f64>,
    nees_pos: Vec<f64>,
    nees_tau: Vec<f64>,
}

impl McSink {
    fn put(v: &mut Vec<f64>, k: usize, x: f64) {
        if v.len() <= k {
            v.resize(k + 1, f64::NAN);
        }
        v[k] = x;
    }
}

impl NavSink for McSink {
    fn nav(&mut self, nav: &NavState, _imu: &ImuErrors) -> Result<(), Error> {
        let scorer = match &mut self.scorer {
            Some(s) => s,
            None => self.scorer.insert(TruthScorer::open(&self.truth_path)?),
        };
        self.last = scorer.score(nav)?;
        if let Some(e) = &self.last {
            self.ev.push(e);
        }
        Ok(())
    }

    fn aux(
        &mut self,
        time: GpsTime,
        _imu: &ImuErrors,
        _sd: &[f64],
        offset: Option<TimeOffsetState>,
    ) -> Result<(), Error> {
        let t = time.seconds_since(self.start);
        if t < 0.0 {
            return Ok(());
        }
        let k = (t / self.step_s).floor() as usize;
        if k < self.next_k {
            return Ok(());
        }
        self.next_k = k + 1;
        self.want = Some(k);
        if let (Some(o), Some(tau)) = (offset, self.tau_true)
            && o.sd_s > 0.0
        {
            Self::put(&mut self.nees_tau, k, ((o.offset_s - tau) / o.sd_s).powi(2));
        }
        Ok(())
    }

    fn position_covariance(&mut self, _time: GpsTime, p: &Matrix3<f64>) -> Result<(), Error> {
        let (Some(k), Some(e)) = (self.want.take(), self.last) else {
            return Ok(());
        };
        if let Some(chol) = p.cholesky() {
            let x: Vector3<f64> = e.pos_ned_m;
            Self::put(&mut self.nees_pos, k, x.dot(&chol.solve(&x)));
        }
        Ok(())
    }
}

/// One run of the chain with seed `seed`, scored in memory.
fn run_one(base: &Scenario, seed: u64, opts: &McOptions) -> Result<RunFigures, Error> {
    let started = Instant::now();
    let scn = Scenario {
        seed,
        ..base.clone()
    };
    let sim = Simulation::new(scn.clone())?;
    let root = opts.work_dir.join(format!("run-{seed:05}"));
    let dirs = ChainDirs::under(&root);
    let mut chain = ChainOptions::for_scenario(&scn);
    if opts.smooth {
        chain.fuse.smooth = Some(navsync::pipeline::SmoothOptions::default());
    }
    let tau_true = true_time_offset_s(&scn);
    let mut sink = McSink {
        truth_path: dirs.sim.join("truth.nav"),
        scorer: None,
        ev: Evaluator::new(&outage_windows(&scn)),
        last: None,
        start: sim.start(),
        step_s: opts.nees_step_s,
        next_k: 0,
        want: None,
        tau_true,
        nees_pos: Vec::new(),
        nees_tau: Vec::new(),
    };
    let result = run_chain(&sim, &dirs, &chain, &mut sink, &mut |_, _| {});
    if !opts.keep_files {
        let _ = std::fs::remove_dir_all(&root);
    }
    let run = result?;
    let r: EvalReport = sink.ev.finish();
    if r.epochs_compared == 0 {
        return Err(Error::Invalid(format!(
            "seed {seed}: no solution epoch overlaps the truth"
        )));
    }
    let truth = run.sync.report.truth.as_ref();
    let tau = run.fuse.time_offset_s;
    Ok(RunFigures {
        seed,
        pos_horizontal_rms_m: r.pos_horizontal_m.rms,
        pos_3d_rms_m: r.pos_3d_m.rms,
        outage_rms_max_horizontal_m: r.outage_rms_max_horizontal_m,
        outage_worst_horizontal_m: r.outage_worst_horizontal_m,
        sync_rms_us: truth.map(|t| t.rms_us),
        sync_max_us: truth.map(|t| t.max_abs_us),
        time_offset_s: tau,
        time_offset_sd_s: run.fuse.time_offset_sd_s,
        time_offset_error_s: tau.zip(tau_true).map(|(a, b)| a - b),
        gnss_fixes_rejected: run.fuse.stats.gnss_fixes_rejected,
        run_time_s: started.elapsed().as_secs_f64(),
        nees_pos: sink.nees_pos,
        nees_tau: sink.nees_tau,
    })
}

/// Runs the study; `progress(done, total)` is called as runs finish (from
/// the worker threads).
pub fn run(
    base: &Scenario,
    opts: &McOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<McReport, Error> {
    if opts.runs == 0 || opts.jobs == 0 {
        return Err(Error::Invalid("runs and jobs must be at least 1".into()));
    }
    if opts.nees_step_s.is_nan() || opts.nees_step_s <= 0.0 {
        return Err(Error::Invalid("the NEES step must be positive".into()));
    }
    // Check the scenario once before starting the workers.
    let duration_s = Simulation::new(base.clone())?.duration_s();
    std::fs::create_dir_all(&opts.work_dir).map_err(|e| Error::io(&opts.work_dir, e))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs)
        .thread_name(|i| format!("montecarlo-{i}"))
        .build()
        .map_err(|e| Error::Invalid(format!("thread pool: {e}")))?;
    let started = Instant::now();
    let done = AtomicUsize::new(0);
    let rows: Vec<RunFigures> = pool.install(|| {
        (0..opts.runs)
            .into_par_iter()
            .map(|i| {
                let r = run_one(base, opts.first_seed + i as u64, opts);
                progress(done.fetch_add(1, Ordering::Relaxed) + 1, opts.runs);
                r
            })
            .collect::<Result<Vec<_>, Error>>()
    })?;
    let wall_time_s = started.elapsed().as_secs_f64();
    Ok(summarize(base, opts, duration_s, wall_time_s, rows))
}

fn summarize(
    base: &Scenario,
    opts: &McOptions,
    duration_s: f64,
    wall_time_s: f64,
    rows: Vec<RunFigures>,
) -> McReport {
    let col = |f: &dyn Fn(&RunFigures) -> Option<f64>| rows.iter().filter_map(f).collect();
    let mut figures = vec![
        Distribution::of(
            "position RMS, horizontal",
            "m",
            col(&|r| Some(r.pos_horizontal_rms_m)),
        ),
        Distribution::of("position RMS, 3D", "m", col(&|r| Some(r.pos_3d_rms_m))),
    ];
    if rows.iter().any(|r| r.outage_rms_max_horizontal_m.is_some()) {
        figures.push(Distribution::of(
            "outage drift (RMS of max horizontal)",
            "m",
            col(&|r| r.outage_rms_max_horizontal_m),
        ));
    }
    if rows.iter().any(|r| r.sync_rms_us.is_some()) {
        figures.push(Distribution::of(
            "sync error RMS vs truth",
            "µs",
            col(&|r| r.sync_rms_us),
        ));
        figures.push(Distribution::of(
            "sync error max vs truth",
            "µs",
            col(&|r| r.sync_max_us),
        ));
    }
    if rows.iter().any(|r| r.time_offset_error_s.is_some()) {
        figures.push(Distribution::of(
            "time-offset error |τ̂ − τ|",
            "ms",
            col(&|r| r.time_offset_error_s.map(|e| e.abs() * 1e3)),
        ));
        figures.push(Distribution::of(
            "time-offset σ (filter)",
            "ms",
            col(&|r| r.time_offset_sd_s.map(|s| s * 1e3)),
        ));
    }
    let pos: Vec<&[f64]> = rows.iter().map(|r| r.nees_pos.as_slice()).collect();
    let tau: Vec<&[f64]> = rows.iter().map(|r| r.nees_tau.as_slice()).collect();
    let has_tau = tau.iter().any(|v| !v.is_empty());
    McReport {
        tool: "navsync montecarlo",
        version: env!("CARGO_PKG_VERSION"),
        scenario: base.clone(),
        runs: rows.len(),
        jobs: opts.jobs,
        duration_s,
        true_time_offset_s: true_time_offset_s(base),
        wall_time_s,
        figures,
        nees_position: NeesTest::of("position", 3, &pos, opts.nees_step_s, opts.nees_skip_s),
        nees_time_offset: has_tau
            .then(|| NeesTest::of("time offset", 1, &tau, opts.nees_step_s, opts.nees_skip_s)),
        per_run: rows,
    }
}

impl McReport {
    /// The tables as text.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:<40} {:>6} {:>10} {:>10} {:>10} {:>10}",
            "figure (over runs)", "unit", "mean", "p50", "p95", "max"
        );
        for d in &self.figures {
            let _ = writeln!(
                s,
                "{:<40} {:>6} {:>10.4} {:>10.4} {:>10.4} {:>10.4}",
                d.name, d.unit, d.mean, d.p50, d.p95, d.max
            );
        }
        let t = &self.nees_position;
        let _ = writeln!(
            s,
            "\nconsistency: average NEES over {} runs (Bar-Shalom et al. 2001 §5.4.2), one epoch every {} s, the first {} s left out",
            self.runs, t.step_s, t.skip_s
        );
        let _ = writeln!(
            s,
            "{:<14} {:>4} {:>20} {:>10} {:>9} {:>9} {:>9}",
            "state", "dof", "95% bounds", "mean", "inside", "above", "below"
        );
        for t in std::iter::once(&self.nees_position).chain(self.nees_time_offset.as_ref()) {
            let _ = writeln!(
                s,
                "{:<14} {:>4} {:>9.3} … {:<8.3} {:>10.3} {:>8.1}% {:>8.1}% {:>8.1}%",
                t.state,
                t.dof,
                t.lower,
                t.upper,
                t.mean_anees,
                100.0 * t.fraction_inside,
                100.0 * t.fraction_above,
                100.0 * t.fraction_below
            );
        }
        s
    }
}

/// Writes `report` as `dir/montecarlo.json`.
pub fn write_json(report: &McReport, dir: &Path) -> Result<PathBuf, Error> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let p = dir.join("montecarlo.json");
    let json = serde_json::to_string_pretty(report).map_err(|e| Error::Invalid(e.to_string()))?;
    navsync::io::output::write_file(&p, json)?;
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::base_layer;

    #[test]
    fn nees_region_and_counts() {
        // 50 runs, 3 dof: χ²₁₅₀(0.025)/50 and χ²₁₅₀(0.975)/50 (tables:
        // 117.985 and 185.800).
        let ok = vec![3.0; 40];
        let high = vec![9.0; 40];
        let mut runs: Vec<&[f64]> = vec![&ok; 49];
        runs.push(&high);
        let t = NeesTest::of("position", 3, &runs, 1.0, 10.0);
        assert!((t.lower - 117.985 / 50.0).abs() < 1e-3, "{}", t.lower);
        assert!((t.upper - 185.800 / 50.0).abs() < 1e-3, "{}", t.upper);
        assert_eq!(t.epochs, 30);
        assert_eq!(t.series.len(), 40);
        // ε̄ = (49·3 + 9)/50 = 3.12: inside.
        assert!((t.mean_anees - 3.12).abs() < 1e-12);
        assert_eq!(t.fraction_inside, 1.0);
        let all_high: Vec<&[f64]> = vec![&high; 50];
        let t = NeesTest::of("position", 3, &all_high, 1.0, 10.0);
        assert_eq!((t.fraction_above, t.fraction_inside), (1.0, 0.0));
    }

    #[test]
    fn a_small_study_runs_the_whole_chain() {
        let mut layer = base_layer("demo").unwrap();
        crate::scenario::set_path(&mut layer, "duration_s", serde_json::json!(200.0)).unwrap();
        let scn = Scenario::from_layer(layer).unwrap();
        let dir = navsync::testfiles::TestDir::new("mc-test");
        let opts = McOptions {
            runs: 3,
            jobs: 2,
            work_dir: dir.to_path_buf(),
            ..McOptions::default()
        };
        let calls = AtomicUsize::new(0);
        let r = run(&scn, &opts, &|_, total| {
            assert_eq!(total, 3);
            calls.fetch_add(1, Ordering::Relaxed);
        })
        .unwrap();
        assert_eq!(calls.load(Ordering::Relaxed), 3);
        assert_eq!(r.runs, 3);
        let seeds: Vec<u64> = r.per_run.iter().map(|x| x.seed).collect();
        assert_eq!(seeds, [1, 2, 3]);
        // Other seeds, other errors.
        assert_ne!(
            r.per_run[0].pos_horizontal_rms_m,
            r.per_run[1].pos_horizontal_rms_m
        );
        for x in &r.per_run {
            assert!(x.pos_horizontal_rms_m < 3.0, "{x:?}");
            assert!(x.sync_rms_us.unwrap() < 2.0, "{x:?}");
            // τ converged: over 50 such runs (seeds 1…50, 200 s) the filter's
            // σ was 0.94–0.95 ms and the worst error 2.49 ms (2.6σ; NEES 1.08),
            // so 4σ fails only a filter that did not converge (τ = 10 ms).
            let sd = x.time_offset_sd_s.unwrap();
            assert!(sd < 1.5e-3, "{x:?}");
            assert!(x.time_offset_error_s.unwrap().abs() < 4.0 * sd, "{x:?}");
            // One NEES epoch per second of the run.
            assert!(
                (195..=201).contains(&x.nees_pos.len()),
                "{}",
                x.nees_pos.len()
            );
        }
        for d in &r.figures {
            assert!(d.p50 <= d.p95 && d.p95 <= d.max && d.runs == 3, "{d:?}");
        }
        assert!(r.nees_time_offset.is_some());
        // Every run's files are gone.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        assert!(r.table().contains("position RMS, horizontal"));
    }
}
