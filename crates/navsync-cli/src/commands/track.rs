//! `navsync track`: simulated carrier tracking against C/N0, unaided or
//! with Doppler aiding from an integrated navigation solution, with a
//! fixed or adaptive loop bandwidth (seed 003).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail, ensure};
use navsync::Diagnostics;
use navsync_report::tracking::{PhaseErrorPoint, phase_error_svg};
use navsync_tracking::aiding::{AidingErrorConfig, AidingStats};
use navsync_tracking::channel::BandwidthMode;
use navsync_tracking::design::AdaptiveConfig;
use navsync_tracking::discriminator::Discriminator;
use navsync_tracking::dynamics::{LandVehicleOptions, SatelliteLos};
use navsync_tracking::loop_filter::LoopOrder;
use navsync_tracking::oscillator::AllanCoefficients;
use navsync_tracking::scenario::{self, Scenario};
use navsync_tracking::sim::{self, Threshold, TrackConfig, TrackResult};

use super::args;
use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    /// Receiver motion: `land` (generated land-vehicle drive, jerk ≤ 1 g/s),
    /// `static`, or `nav:FILE` (an 11-column navigation/truth file).
    #[arg(long, default_value = "land")]
    pub scenario: String,
    /// C/N0 values (dB-Hz): `A:B` (1 dB steps), `A:B:STEP`, or `A,B,C`.
    #[arg(long, default_value = "20:45")]
    pub cn0: String,
    /// Doppler aiding from the navigation solution.
    #[arg(long, value_enum, default_value_t = Aiding::None)]
    pub aiding: Aiding,
    /// Aiding error: `kf:RAMP,SD,TAU,T` (Hz/s, Hz, s, s: ramp reset and GM
    /// held at each filter update every T), `gm:SD,TAU,T`, `ramp:RATE`
    /// (constant Doppler-rate error), `varying[:PERIOD]` (good and poor
    /// aiding alternating every PERIOD s, default 30), `cov:STD_FILE[,TAU]`
    /// (velocity σ of a `navsync fuse` std.txt along the line of sight), `none`.
    #[arg(long, default_value = "kf:0.05,0.05,5,1")]
    pub aiding_error: String,
    /// Loop noise bandwidth (Hz) or `adaptive`.
    #[arg(long, default_value = "15")]
    pub bandwidth: String,
    /// Loop order [default: 3 unaided, 2 aided].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=3))]
    pub order: Option<u32>,
    /// Coherent integration time (ms): 1–20, dividing 20 with data bits.
    #[arg(value_parser = args::count_u32(1, 20), long, default_value_t = 1)]
    pub t_coh: u32,
    #[arg(long, value_enum, default_value_t = Disc::Costas)]
    pub discriminator: Disc,
    /// A pilot signal: no navigation data bits.
    #[arg(long)]
    pub pilot: bool,
    /// Normalise the discriminator by its gain at the estimated C/N0
    /// [default: on for adaptive bandwidth, off for fixed].
    #[arg(long, value_enum, default_value_t = Switch::Auto)]
    pub gain_normalization: Switch,
    /// Receiver oscillator: `tcxo`, `tcxo-low`, `ocxo`, `ideal`, or `h0,h-1,h-2`.
    #[arg(long, default_value = "tcxo")]
    pub oscillator: String,
    /// Satellite elevation and azimuth (deg).
    #[arg(value_parser = args::real(-90.0, 90.0, "deg"), long, default_value_t = 30.0)]
    pub elevation: f64,
    #[arg(value_parser = args::symmetric(360.0, "deg"), long, default_value_t = 45.0)]
    pub azimuth: f64,
    /// Satellite range rate (m/s) and range acceleration (m/s²) from its own motion.
    #[arg(value_parser = args::symmetric(1e4, "m/s"), long, default_value_t = 300.0)]
    pub sat_rate: f64,
    #[arg(value_parser = args::symmetric(100.0, "m/s²"), long, default_value_t = 0.1)]
    pub sat_accel: f64,
    /// Simulated seconds per C/N0 point.
    #[arg(value_parser = args::real(1.0, 86_400.0, "s"), long, default_value_t = 120.0)]
    pub duration: f64,
    /// Seconds excluded from the statistics at the start.
    #[arg(value_parser = args::non_negative(3600.0, "s"), long, default_value_t = 2.0)]
    pub settle: f64,
    /// Adaptive bandwidth limits (Hz) and slew (factor per second).
    #[arg(value_parser = args::real(0.01, 100.0, "Hz"), long, default_value_t = 0.5)]
    pub bn_min: f64,
    #[arg(value_parser = args::real(0.01, 100.0, "Hz"), long, default_value_t = 25.0)]
    pub bn_max: f64,
    #[arg(value_parser = args::positive(100.0, ""), long, default_value_t = 2.0)]
    pub bn_slew: f64,
    /// Also run these fixed bandwidths (Hz, comma-separated) and compare the
    /// RMS phase error with the best of them at each C/N0.
    #[arg(long)]
    pub compare_fixed: Option<String>,
    #[arg(value_parser = args::seed(), long, default_value_t = 1)]
    pub seed: u64,
    /// Write the table as CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Plot 3σ+|bias|, RMS and the prediction against C/N0 (SVG).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Write everything (configuration, results, thresholds) as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a 10 Hz time series (phase error, bandwidth, C/N0 estimate,
    /// aiding error) of the run at this C/N0 as CSV.
    #[arg(long, value_names = ["CN0", "FILE"], num_args = 2)]
    pub series: Option<Vec<String>>,
}

#[derive(Copy, Clone, PartialEq, Eq, clap::ValueEnum)]
pub enum Aiding {
    None,
    Ins,
}

#[derive(Copy, Clone, PartialEq, Eq, clap::ValueEnum)]
pub enum Switch {
    Auto,
    On,
    Off,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Disc {
    /// atan(Q/I), data-tolerant
    Costas,
    /// atan2(Q, I), needs data wipe-off
    Pll,
}

/// Parses `A:B`, `A:B:STEP` or `A,B,...`.
pub fn parse_cn0_list(s: &str) -> Result<Vec<f64>> {
    let num = |x: &str| -> Result<f64> {
        x.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .with_context(|| format!("--cn0: '{x}' is not a number"))
    };
    if s.contains(':') {
        let p: Vec<&str> = s.split(':').collect();
        ensure!(
            p.len() == 2 || p.len() == 3,
            "--cn0: expected A:B or A:B:STEP, got '{s}'"
        );
        let (a, b) = (num(p[0])?, num(p[1])?);
        let step = if p.len() == 3 { num(p[2])? } else { 1.0 };
        ensure!(step > 0.0 && b >= a, "--cn0: need A ≤ B and STEP > 0");
        let n = ((b - a) / step + 1e-9).floor() as usize;
        ensure!(n < 1000, "--cn0: too many points");
        Ok((0..=n).map(|i| a + step * i as f64).collect())
    } else {
        s.split(',').map(num).collect()
    }
}

fn parse_numbers(s: &str, what: &str, n: usize) -> Result<Vec<f64>> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("{what}: '{x}' is not a number"))
        })
        .collect::<Result<_>>()?;
    ensure!(
        v.len() == n,
        "{what}: expected {n} comma-separated numbers, got {}",
        v.len()
    );
    Ok(v)
}

fn parse_aiding_error(
    s: &str,
    duration_s: f64,
    los: &SatelliteLos,
    lambda: f64,
) -> Result<AidingErrorConfig> {
    let (kind, rest) = s.split_once(':').unwrap_or((s, ""));
    Ok(match kind {
        "none" => AidingErrorConfig::None,
        "ramp" => AidingErrorConfig::ConstantRamp {
            rate_hz_s: parse_numbers(rest, "--aiding-error ramp", 1)?[0],
        },
        "kf" => {
            let v = parse_numbers(rest, "--aiding-error kf:RAMP,SD,TAU,T", 4)?;
            ensure!(
                v.iter().all(|x| *x >= 0.0) && v[3] > 0.0,
                "--aiding-error kf: values must be ≥ 0 and T > 0"
            );
            AidingErrorConfig::constant(AidingStats {
                ramp_hz_s: v[0],
                gm_sd_hz: v[1],
                gm_tau_s: v[2],
                update_period_s: v[3],
            })
        }
        "gm" => {
            let v = parse_numbers(rest, "--aiding-error gm:SD,TAU,T", 3)?;
            ensure!(
                v.iter().all(|x| *x >= 0.0) && v[2] > 0.0,
                "--aiding-error gm: values must be ≥ 0 and T > 0"
            );
            AidingErrorConfig::constant(AidingStats {
                ramp_hz_s: 0.0,
                gm_sd_hz: v[0],
                gm_tau_s: v[1],
                update_period_s: v[2],
            })
        }
        "varying" => {
            let period = if rest.is_empty() {
                30.0
            } else {
                parse_numbers(rest, "--aiding-error varying:PERIOD", 1)?[0]
            };
            ensure!(
                period > 0.0,
                "--aiding-error varying: PERIOD must be positive"
            );
            scenario::varying_aiding(period, duration_s)
        }
        "cov" => {
            let (path, tau) = match rest.rsplit_once(',') {
                Some((p, t)) if t.trim().parse::<f64>().is_ok() => (p, t.trim().parse::<f64>()?),
                _ => (rest, 5.0),
            };
            ensure!(!path.is_empty(), "--aiding-error cov: needs a std.txt path");
            let mut d = Diagnostics::default();
            let series =
                scenario::read_los_velocity_sd(std::path::Path::new(path), &los.unit_ned, &mut d)?;
            if !d.is_empty() {
                eprintln!("{} lines of {path} skipped:", d.total);
                print_diagnostics(&d, 5);
            }
            AidingErrorConfig::from_velocity_sd(&series, lambda, tau)
        }
        _ => bail!("--aiding-error: unknown kind '{kind}' (kf, gm, ramp, varying, cov, none)"),
    })
}

fn parse_oscillator(s: &str) -> Result<AllanCoefficients> {
    if let Some(p) = AllanCoefficients::preset(s) {
        return Ok(p);
    }
    let v = parse_numbers(
        s,
        "--oscillator (tcxo, tcxo-low, ocxo, ideal or h0,h-1,h-2)",
        3,
    )?;
    ensure!(
        v.iter().all(|x| *x >= 0.0),
        "--oscillator: h coefficients must be ≥ 0"
    );
    Ok(AllanCoefficients {
        h0: v[0],
        h_m1: v[1],
        h_m2: v[2],
    })
}

fn fmt_threshold(t: Option<Threshold>) -> String {
    match t {
        None => "n/a".into(),
        Some(t) if t.above_range => {
            format!("above {:.1} dB-Hz (fails at every C/N0 tried)", t.dbhz)
        }
        Some(t) if t.at_or_below => format!("≤ {:.1} dB-Hz (holds at every C/N0 tried)", t.dbhz),
        Some(t) => format!("{:.1} dB-Hz", t.dbhz),
    }
}

pub fn run(args: Args) -> Result<()> {
    let cn0s = parse_cn0_list(&args.cn0)?;
    ensure!(!cn0s.is_empty(), "--cn0: no values");
    let aided = args.aiding == Aiding::Ins;
    let order_n = args.order.unwrap_or(if aided { 2 } else { 3 });
    let order = LoopOrder::from_number(order_n).context("--order must be 1, 2 or 3")?;
    let discriminator = match args.discriminator {
        Disc::Costas => Discriminator::Costas,
        Disc::Pll => Discriminator::Pll,
    };
    ensure!(
        args.bn_min > 0.0 && args.bn_max >= args.bn_min && args.bn_slew >= 1.0,
        "need 0 < --bn-min ≤ --bn-max and --bn-slew ≥ 1"
    );
    let adaptive_cfg = AdaptiveConfig {
        min_hz: args.bn_min,
        max_hz: args.bn_max,
        slew_per_s: args.bn_slew,
        ..AdaptiveConfig::default()
    };
    let bandwidth = if args.bandwidth == "adaptive" {
        BandwidthMode::Adaptive {
            cfg: adaptive_cfg,
            initial_hz: if aided { 5.0f64 } else { 15.0f64 }.clamp(args.bn_min, args.bn_max),
        }
    } else {
        let b: f64 = args
            .bandwidth
            .parse()
            .ok()
            .filter(|b: &f64| *b > 0.0 && b.is_finite())
            .context("--bandwidth: a positive number of Hz or `adaptive`")?;
        BandwidthMode::Fixed(b)
    };
    let los = SatelliteLos::from_elevation_azimuth(
        args.elevation.to_radians(),
        args.azimuth.to_radians(),
        args.sat_rate,
        args.sat_accel,
    );
    let mut diag = Diagnostics::default();
    let scen = match args.scenario.as_str() {
        "static" => Scenario::Static,
        "land" => Scenario::Land(LandVehicleOptions {
            duration_s: args.duration + 1.0,
            seed: args.seed,
            ..Default::default()
        }),
        s if s.starts_with("nav:") => Scenario::NavFile(PathBuf::from(&s[4..])),
        s => bail!("--scenario: unknown '{s}' (land, static, nav:FILE)"),
    };
    let traj = scenario::trajectory(&scen, &mut diag)?;
    if !diag.is_empty() {
        eprintln!("{} lines of the trajectory file skipped:", diag.total);
        print_diagnostics(&diag, 5);
    }
    ensure!(
        traj.duration_s() >= args.duration,
        "--duration {} s is longer than the trajectory ({:.1} s)",
        args.duration,
        traj.duration_s()
    );
    let base = TrackConfig {
        cn0_dbhz: cn0s[0],
        t_coh_s: args.t_coh as f64 * 1e-3,
        order,
        bandwidth,
        discriminator,
        data_bits: !args.pilot,
        oscillator: parse_oscillator(&args.oscillator)?,
        aided,
        duration_s: args.duration,
        settle_s: args.settle,
        seed: args.seed,
        normalize_gain: match args.gain_normalization {
            Switch::Auto => matches!(bandwidth, BandwidthMode::Adaptive { .. }),
            Switch::On => true,
            Switch::Off => false,
        },
        ..TrackConfig::default()
    };
    let lambda = base.wavelength_m();
    let base = TrackConfig {
        aiding_error: if aided {
            parse_aiding_error(&args.aiding_error, args.duration, &los, lambda)?
        } else {
            AidingErrorConfig::None
        },
        ..base
    };
    base.validate()?;

    let label = format!(
        "{} loop, order {}, Bn {}, T {} ms, {}{}{}, oscillator {}",
        if aided { "INS-aided" } else { "unaided" },
        order_n,
        match bandwidth {
            BandwidthMode::Fixed(b) => format!("{b} Hz"),
            BandwidthMode::Adaptive { .. } =>
                format!("adaptive [{}, {}] Hz", args.bn_min, args.bn_max),
        },
        args.t_coh,
        match discriminator {
            Discriminator::Costas => "Costas",
            Discriminator::Pll => "PLL",
        },
        if args.pilot { " (pilot)" } else { "" },
        if base.normalize_gain {
            ", gain-normalised"
        } else {
            ""
        },
        args.oscillator
    );
    println!("navsync track: {label}");
    println!(
        "  scenario {}, satellite el {}° az {}°, {} s per point, seed {}{}",
        args.scenario,
        args.elevation,
        args.azimuth,
        args.duration,
        args.seed,
        if aided {
            format!(", aiding error {}", args.aiding_error)
        } else {
            String::new()
        }
    );
    let started = std::time::Instant::now();
    let results = sim::sweep(&base, &cn0s, traj.as_ref(), &los)?;

    // Optional comparison with fixed bandwidths.
    let mut best_fixed: Vec<Option<(f64, f64)>> = vec![None; results.len()];
    if let Some(list) = &args.compare_fixed {
        let bws: Vec<f64> = list
            .split(',')
            .map(|x| {
                x.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|b| *b > 0.0)
                    .with_context(|| format!("--compare-fixed: '{x}' is not a bandwidth"))
            })
            .collect::<Result<_>>()?;
        for bw in bws {
            let cfg = TrackConfig {
                bandwidth: BandwidthMode::Fixed(bw),
                ..base.clone()
            };
            for (i, r) in sim::sweep(&cfg, &cn0s, traj.as_ref(), &los)?
                .iter()
                .enumerate()
            {
                if best_fixed[i].is_none_or(|(_, rms)| r.rms_deg < rms) {
                    best_fixed[i] = Some((bw, r.rms_deg));
                }
            }
        }
    }

    let mut table = String::new();
    let _ = writeln!(
        table,
        "{:>6} {:>7} {:>17} {:>8} {:>9} {:>8} {:>8} {:>9} {:>9} {:>8} {:>6}{}",
        "C/N0",
        "est",
        "Bn mean [min-max]",
        "jitter°",
        "Kaplan σt",
        "bias°",
        "RMS°",
        "3σ+|b|°",
        "pred 3σ°",
        "slip/min",
        "lock%",
        if args.compare_fixed.is_some() {
            "  best-fixed(Hz) RMS°  ratio"
        } else {
            ""
        }
    );
    for (r, bf) in results.iter().zip(&best_fixed) {
        let _ = write!(
            table,
            "{:>6.1} {:>7.1} {:>6.2} [{:>4.1}-{:>4.1}] {:>8.2} {:>9.2} {:>8.2} {:>8.2} {:>9.1} {:>9.1} {:>8.2} {:>6.1}",
            r.cn0_dbhz,
            r.cn0_est_dbhz,
            r.bn_mean_hz,
            r.bn_min_hz,
            r.bn_max_hz,
            r.jitter_deg,
            r.kaplan_thermal_deg,
            r.bias_deg,
            r.rms_deg,
            r.three_sigma_deg,
            r.predicted.three_sigma_rad().to_degrees(),
            r.slips_per_min,
            100.0 * r.lock_fraction
        );
        if let Some((bw, rms)) = bf {
            let _ = write!(
                table,
                "  {:>10.1} {:>8.2} {:>6.3}",
                bw,
                rms,
                r.rms_deg / rms
            );
        }
        table.push('\n');
    }
    print!("{table}");
    let t3 = sim::threshold_three_sigma(&results, discriminator);
    let ts = sim::threshold_slips(&results);
    println!(
        "  tracking threshold (3σ+|bias| ≤ {}°, Kaplan's rule of thumb): {}",
        discriminator.threshold_deg(),
        fmt_threshold(t3)
    );
    println!(
        "  slip threshold (< 1 cycle slip per minute): {}",
        fmt_threshold(ts)
    );
    if let Some(t) = t3 {
        let above: Vec<&TrackResult> = results.iter().filter(|r| r.cn0_dbhz >= t.dbhz).collect();
        let worst = above.iter().map(|r| r.slips_per_min).fold(0.0, f64::max);
        println!("  slips above the 3σ threshold: at most {worst:.2} per minute");
    }
    if args.compare_fixed.is_some() {
        let worst = results
            .iter()
            .zip(&best_fixed)
            .filter_map(|(r, b)| b.map(|(_, rms)| r.rms_deg / rms))
            .fold(0.0, f64::max);
        println!("  RMS phase error / best fixed bandwidth's: at most {worst:.3}");
    }
    println!("  {:.1} s", started.elapsed().as_secs_f64());

    if let Some(p) = &args.csv {
        let mut s = String::from(
            "cn0_dbhz,cn0_est_dbhz,bn_mean_hz,bn_min_hz,bn_max_hz,jitter_deg,kaplan_thermal_deg,bias_deg,rms_deg,three_sigma_deg,predicted_three_sigma_deg,predicted_thermal_deg,predicted_oscillator_deg,predicted_aiding_deg,predicted_bias_deg,slips,slips_per_min,lock_fraction,best_fixed_hz,best_fixed_rms_deg\n",
        );
        for (r, bf) in results.iter().zip(&best_fixed) {
            let b = &r.predicted;
            let _ = writeln!(
                s,
                "{},{:.3},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{:.4},{:.4},{},{}",
                r.cn0_dbhz,
                r.cn0_est_dbhz,
                r.bn_mean_hz,
                r.bn_min_hz,
                r.bn_max_hz,
                r.jitter_deg,
                r.kaplan_thermal_deg,
                r.bias_deg,
                r.rms_deg,
                r.three_sigma_deg,
                b.three_sigma_rad().to_degrees(),
                b.thermal_rad.to_degrees(),
                b.oscillator_rad.to_degrees(),
                b.aiding_rad.to_degrees(),
                b.bias_rad.to_degrees(),
                r.slips,
                r.slips_per_min,
                r.lock_fraction,
                bf.map(|x| x.0.to_string()).unwrap_or_default(),
                bf.map(|x| format!("{:.4}", x.1)).unwrap_or_default(),
            );
        }
        navsync::io::output::write_file(p, s)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("  wrote {}", p.display());
    }
    if let Some(p) = &args.svg {
        let points: Vec<PhaseErrorPoint> = results
            .iter()
            .zip(&best_fixed)
            .map(|(r, b)| PhaseErrorPoint {
                cn0_dbhz: r.cn0_dbhz,
                measured_3sigma_deg: r.three_sigma_deg,
                predicted_3sigma_deg: r.predicted.three_sigma_rad().to_degrees(),
                rms_deg: r.rms_deg,
                best_fixed_rms_deg: b.map(|(_, rms)| rms),
            })
            .collect();
        phase_error_svg(p, &label, &points, discriminator.threshold_deg())?;
        println!("  wrote {}", p.display());
    }
    if let Some(p) = &args.json {
        let results_no_series: Vec<TrackResult> = results
            .iter()
            .map(|r| TrackResult {
                series: Vec::new(),
                ..r.clone()
            })
            .collect();
        let j = serde_json::json!({
            "config": base,
            "scenario": args.scenario,
            "results": results_no_series,
            "threshold_three_sigma": t3,
            "threshold_slips": ts,
        });
        navsync::io::output::write_file(p, serde_json::to_string_pretty(&j)?)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("  wrote {}", p.display());
    }
    if let Some(v) = &args.series {
        let cn0: f64 = v[0]
            .parse()
            .ok()
            .filter(|c: &f64| c.is_finite())
            .context("--series: CN0 must be a number")?;
        let cfg = TrackConfig {
            cn0_dbhz: cn0,
            record_interval_s: 0.1,
            ..base.clone()
        };
        let r = sim::run(&cfg, traj.as_ref(), &los)?;
        let mut s = String::from("t_s,phase_error_deg,bn_hz,cn0_est_dbhz,aiding_error_hz\n");
        for x in &r.series {
            let _ = writeln!(
                s,
                "{:.3},{:.4},{:.4},{:.3},{:.5}",
                x.t_s, x.phase_error_deg, x.bn_hz, x.cn0_est_dbhz, x.aiding_error_hz
            );
        }
        navsync::io::output::write_file(&v[1], s).with_context(|| format!("writing {}", v[1]))?;
        println!("  wrote {} (time series at {cn0} dB-Hz)", v[1]);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cn0_lists() {
        assert_eq!(
            parse_cn0_list("25:28").unwrap(),
            vec![25.0, 26.0, 27.0, 28.0]
        );
        assert_eq!(parse_cn0_list("20:21:0.5").unwrap(), vec![20.0, 20.5, 21.0]);
        assert_eq!(parse_cn0_list("30,35").unwrap(), vec![30.0, 35.0]);
        assert!(parse_cn0_list("30:20").is_err());
        assert!(parse_cn0_list("a:b").is_err());
        assert!(parse_cn0_list("1:2:0").is_err());
    }

    #[test]
    fn aiding_error_specs() {
        let los = SatelliteLos::from_elevation_azimuth(0.5, 0.5, 0.0, 0.0);
        let k = parse_aiding_error("kf:0.1,0.2,5,1", 60.0, &los, 0.19).unwrap();
        assert_eq!(
            k.stats_at(0.0),
            AidingStats {
                ramp_hz_s: 0.1,
                gm_sd_hz: 0.2,
                gm_tau_s: 5.0,
                update_period_s: 1.0
            }
        );
        assert!(
            matches!(parse_aiding_error("ramp:1", 60.0, &los, 0.19).unwrap(), AidingErrorConfig::ConstantRamp { rate_hz_s } if rate_hz_s == 1.0)
        );
        assert!(parse_aiding_error("kf:1,2", 60.0, &los, 0.19).is_err());
        assert!(parse_aiding_error("bogus", 60.0, &los, 0.19).is_err());
        assert!(parse_aiding_error("cov:/nonexistent/std.txt", 60.0, &los, 0.19).is_err());
        assert!(parse_oscillator("1e-21,0,0").is_ok());
        assert!(parse_oscillator("quartz").is_err());
    }
}
