//! The verdict rows of seed 001 §1 (checklist §1.5) from a report.

use super::*;

/// One verdict row per seed 001 §1 criterion.
pub(super) fn criteria(r: &QualityReport, cfg: &QualityConfig) -> Vec<Criterion> {
    let mut out = Vec::new();
    let log_rate = r.round_rate_hz.unwrap_or(r.true_rate_hz);
    // §1.1: data type.
    out.push(Criterion {
        section: "§1.1",
        rule: "increments for navigation (rates converted by trapezoid)".into(),
        status: Status::Info,
        measured: if r.format == "kf-gins" {
            "increments (used as they are)".into()
        } else {
            "rates: `navsync imu convert` integrates them by trapezoid".into()
        },
        limit: "increments".into(),
    });
    // §1.2 / §1.5-1: raw rate.
    let (status, measured) = match cfg.raw_rate_hz {
        Some(raw) => (
            if raw >= cfg.min_raw_rate_hz {
                Status::Pass
            } else {
                Status::Fail
            },
            format!("raw {raw:.0} Hz (declared), log {log_rate:.2} Hz"),
        ),
        None if log_rate >= cfg.min_raw_rate_hz * 0.999 => (
            Status::Pass,
            format!("log {log_rate:.2} Hz (the raw rate is at least this)"),
        ),
        None => (
            Status::Warn,
            format!(
                "log {log_rate:.2} Hz; raw rate unknown (fine only if the IMU averages a >= {:.0} Hz raw stream; declare it with --raw-rate)",
                cfg.min_raw_rate_hz
            ),
        ),
    };
    out.push(Criterion {
        section: "§1.2, §1.5-1",
        rule: "raw sampling rate >= 10-20x the dynamics (vehicle: 200 Hz)".into(),
        status,
        measured,
        limit: format!(">= {:.0} Hz", cfg.min_raw_rate_hz),
    });
    out.push(Criterion {
        section: "§1.3, §1.5-2",
        rule: "decimation by averaging/accumulation, not point sampling".into(),
        status: Status::Info,
        measured: "not visible in a log; `navsync imu convert --decimate N` averages".into(),
        limit: "average".into(),
    });
    // §1.4 / §1.5-3: low-pass filter.
    // Noise colour of the static segment: lag 1 for rates, lag 2 for
    // increments (see `AllanChannel::lag2_correlation`).
    let (lag, rho_limit) = if r.format == "kf-gins" {
        (2, 0.2)
    } else {
        (1, 0.3)
    };
    let max_rho = r.allan.as_ref().map(|a| {
        a.channels
            .iter()
            .map(|c| {
                if lag == 1 {
                    c.lag1_correlation
                } else {
                    c.lag2_correlation
                }
            })
            .fold(f64::NAN, f64::max)
    });
    let (status, measured) = match (&r.lowpass, max_rho) {
        (Some(lp), _) => (
            Status::Fail,
            format!(
                "declared {}: delay {:.3} ms (compensated by `navsync imu convert --lowpass`)",
                lp.filter.name,
                lp.delay.dc_s * 1e3
            ),
        ),
        (None, Some(rho)) if rho > rho_limit => (
            Status::Warn,
            format!(
                "none declared, but the static noise is correlated (lag-{lag} {rho:.2} > {rho_limit}): a filter looks active"
            ),
        ),
        (None, Some(rho)) => (
            Status::Pass,
            format!("none declared; static noise uncorrelated (lag-{lag} correlation <= {rho:.2})"),
        ),
        (None, None) => (
            Status::Info,
            "none declared (no static segment to test the noise colour)".into(),
        ),
    };
    out.push(Criterion {
        section: "§1.4, §1.5-3",
        rule: "no low-pass filter (or the widest; its delay compensated)".into(),
        status,
        measured,
        limit: "off".into(),
    });
    // §1.5-4: precision.
    let worst = r
        .channels
        .iter()
        .max_by(|a, b| a.rounding_to_noise.total_cmp(&b.rounding_to_noise));
    let typ_sig = r
        .channels
        .iter()
        .map(|c| c.typical_significant_digits)
        .min()
        .unwrap_or(0);
    if let Some(w) = worst {
        let status = if !w.rounding_to_noise.is_finite() {
            Status::Warn
        } else if w.rounding_to_noise <= 0.1 {
            Status::Pass
        } else {
            Status::Fail
        };
        let quant = r
            .channels
            .iter()
            .filter_map(|c| c.quantization_step.map(|q| (c.name, q, c.unit)))
            .map(|(n, q, u)| format!("{n} {q:.3e} {u}"))
            .collect::<Vec<_>>();
        out.push(Criterion {
            section: "§1.5-4",
            rule: "full precision kept (no truncation when written)".into(),
            status,
            measured: format!(
                "typically {typ_sig} significant digits; print rounding {:.1e} of the noise ({}){}",
                w.rounding_to_noise,
                w.name,
                if quant.is_empty() {
                    String::new()
                } else {
                    format!("; sensor resolution {}", quant.join(", "))
                }
            ),
            limit: "rounding <= 0.1 x noise".into(),
        });
    }
    // §1.5-5: continuity.
    out.push(Criterion {
        section: "§1.5-5",
        rule: format!("no gap longer than {} s", cfg.max_gap_s),
        status: if r.counts.gaps_over_limit == 0 {
            Status::Pass
        } else {
            Status::Fail
        },
        measured: format!(
            "longest interval {:.4} s; {} gaps, {} over the limit",
            r.intervals.max_s, r.counts.gaps, r.counts.gaps_over_limit
        ),
        limit: format!("<= {} s", cfg.max_gap_s),
    });
    out.push(Criterion {
        section: "§1.5-5",
        rule: "loss rate".into(),
        status: if r.loss_rate < cfg.max_loss_rate {
            Status::Pass
        } else {
            Status::Fail
        },
        measured: format!(
            "{} lost of {} expected ({})",
            r.counts.lost_samples,
            r.accepted + r.counts.lost_samples,
            fmt_rate(r.loss_rate)
        ),
        limit: format!("< {:.0e}", cfg.max_loss_rate),
    });
    let c = &r.counts;
    out.push(Criterion {
        section: "§1.5-5",
        rule: "bad-data rate".into(),
        status: if r.bad_data_rate < cfg.max_bad_rate { Status::Pass } else { Status::Fail },
        measured: format!(
            "{} bad of {} records ({}): malformed {}, duplicated {}, out of order {}, stale {}, spikes {}, saturated {}, stuck {}",
            r.bad_records,
            r.records,
            fmt_rate(r.bad_data_rate),
            c.malformed_lines,
            c.duplicates,
            c.out_of_order,
            c.stale_records,
            c.spike_records,
            c.saturated_samples,
            c.stuck_samples
        ),
        limit: format!("< {:.0e}", cfg.max_bad_rate),
    });
    let fail_if = |n: usize| if n == 0 { Status::Pass } else { Status::Fail };
    out.push(Criterion {
        section: "§1.5-5",
        rule: "no duplicated or out-of-order records".into(),
        status: fail_if(c.duplicates + c.out_of_order + c.stale_records),
        measured: format!(
            "{} duplicated, {} out of order, {} stale",
            c.duplicates, c.out_of_order, c.stale_records
        ),
        limit: "0".into(),
    });
    out.push(Criterion {
        section: "§1.5-5",
        rule: "no saturated, stuck or spiking channel".into(),
        status: fail_if(c.saturation_events + c.stuck_segments + c.spikes),
        measured: format!(
            "saturation {} ({} samples), stuck {} ({} samples), spikes {}",
            c.saturation_events, c.saturated_samples, c.stuck_segments, c.stuck_samples, c.spikes
        ),
        limit: "0".into(),
    });
    out.push(Criterion {
        section: "§1.5-5",
        rule: "stable acquisition interval (jitter)".into(),
        status: if r.intervals.jitter_rms_frac <= cfg.max_jitter_frac {
            Status::Pass
        } else {
            Status::Fail
        },
        measured: format!(
            "RMS {:.1} us ({:.2} % of {:.3} ms); 99 % within {:.1} us",
            r.intervals.jitter_rms_s * 1e6,
            r.intervals.jitter_rms_frac * 100.0,
            r.intervals.nominal_s * 1e3,
            r.intervals.p99_abs_dev_s * 1e6
        ),
        limit: format!(
            "RMS <= {:.0} % (navsync's limit)",
            cfg.max_jitter_frac * 100.0
        ),
    });
    out.push(Criterion {
        section: "§1.5-5",
        rule: "true sampling rate".into(),
        status: Status::Info,
        measured: match r.round_rate_hz {
            Some(round) => format!(
                "{:.4} Hz ({:+.1} ppm from {round} Hz)",
                r.true_rate_hz, r.rate_error_ppm
            ),
            None => format!(
                "{:.4} Hz (no round rate; the median interval alone would say {:.3} Hz)",
                r.true_rate_hz, r.nominal_rate_hz
            ),
        },
        limit: "-".into(),
    });
    match &r.allan {
        Some(a) => {
            let g: Vec<String> = a.channels[..3]
                .iter()
                .map(|c| format!("{:.3}", c.random_walk_display))
                .collect();
            let v: Vec<String> = a.channels[3..]
                .iter()
                .map(|c| format!("{:.4}", c.random_walk_display))
                .collect();
            let bi: Vec<String> = a.channels[..3]
                .iter()
                .map(|c| {
                    format!(
                        "{}{:.2}",
                        if c.bias_instability_resolved {
                            ""
                        } else {
                            "<="
                        },
                        c.bias_instability_display
                    )
                })
                .collect();
            out.push(Criterion {
                section: "noise",
                rule: "Allan deviation of the longest static segment".into(),
                status: Status::Info,
                measured: format!(
                    "{:.1} s at line {}: ARW {} deg/sqrt(h), VRW {} m/s/sqrt(h), gyro bias instability {} deg/h",
                    a.segment.duration_s,
                    a.segment.first_line,
                    g.join("/"),
                    v.join("/"),
                    bi.join("/")
                ),
                limit: "-".into(),
            });
        }
        None => out.push(Criterion {
            section: "noise",
            rule: "Allan deviation of the longest static segment".into(),
            status: Status::Info,
            measured: format!("no static segment of {} s or more", cfg.min_static_s),
            limit: "-".into(),
        }),
    }
    out
}
