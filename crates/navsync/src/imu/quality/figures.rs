//! The per-channel and per-interval figures of a finished IMU log check
//! ([`QualityAnalyzer::finish`]): stuck runs and saturation, the interval
//! statistics and rate, the channel reports, the static segments and the
//! Allan deviation.

use super::*;

/// Stuck runs and saturation found over the whole log.
pub(super) struct FlatRuns {
    /// Stuck segments per channel.
    pub stuck: [usize; 6],
    /// Saturated samples per channel.
    pub saturated: [usize; 6],
    /// Records stuck or saturated, each counted once.
    pub records: usize,
}

/// The log's rates (Hz) and the true rate's error against the round rate
/// it is near (or the nominal one).
pub(super) struct Rates {
    pub nominal_hz: f64,
    pub round_hz: Option<f64>,
    pub true_hz: f64,
    pub error_ppm: f64,
}

impl QualityAnalyzer {
    /// Stuck runs (longer than chance allows for the channel's repeat rate)
    /// and saturation (flat tops at an extreme, or the declared range),
    /// with their events and counts, over `n_acc` accepted records.
    pub(super) fn flat_runs(&mut self, n_acc: usize) -> FlatRuns {
        let rate = 1.0 / self.nominal_s;
        // Stuck runs: at least 20 samples and `stuck_min_s`, and longer than
        // chance allows for the channel's repeat rate p: n·p^(L−1) < 1e-3.
        let fixed_min = 20usize.max((self.cfg.stuck_min_s * rate).ceil() as usize);
        let mut stuck_ranges: Vec<(usize, usize)> = Vec::new();
        let mut channel_stuck = [0usize; 6];
        let mut channel_sat = [0usize; 6];
        let mut sat_values: [Vec<f64>; 6] = Default::default();
        for c in 0..6 {
            let st = &mut self.ch[c];
            if st.run.len >= 20 {
                st.stuck.push(st.run.clone());
            }
            let in_cands: usize = st.stuck.iter().map(|r| r.len - 1).sum();
            let denom = (n_acc - 1).saturating_sub(in_cands).max(1) as f64;
            let p = ((st.repeats.saturating_sub(in_cands)) as f64 / denom).clamp(1e-12, 0.999);
            let chance_len = 1.0 + (1e-3 / n_acc as f64).ln() / p.ln();
            // Saturation: a flat top at the extreme, as long as chance rules
            // out (≥ 3), or a declared range reached.
            let sat_len = 3f64.max(chance_len.ceil()) as usize;
            for ext in [&st.max, &st.min] {
                if ext.longest >= sat_len
                    && let Some(v) = ext.value
                {
                    channel_sat[c] += ext.in_runs;
                    sat_values[c].push(v);
                }
            }
        }
        for c in 0..6 {
            let scale = if self.format == ImuLogFormat::KfGins {
                1.0 / self.nominal_s
            } else {
                1.0
            };
            let runs = std::mem::take(&mut self.ch[c].stuck);
            let st = &self.ch[c];
            let in_cands: usize = runs.iter().map(|r| r.len - 1).sum();
            let denom = (n_acc - 1).saturating_sub(in_cands).max(1) as f64;
            let p = ((st.repeats.saturating_sub(in_cands)) as f64 / denom).clamp(1e-12, 0.999);
            let chance_len = 1.0 + (1e-3 / n_acc as f64).ln() / p.ln();
            let min_len = (fixed_min as f64).max(chance_len.ceil()) as usize;
            for r in runs.iter().filter(|r| r.len >= min_len) {
                // A long flat top at a saturated extreme is saturation.
                if sat_values[c].contains(&(r.value * scale)) {
                    continue;
                }
                channel_stuck[c] += 1;
                stuck_ranges.push((r.first_idx + 1, r.first_idx + r.len));
                self.counts.stuck_segments += 1;
                self.event(
                    EventKind::Stuck,
                    r.first_line,
                    r.first_ns,
                    Some(c),
                    format!(
                        "value {} repeated {} times ({:.3} s)",
                        r.value,
                        r.len,
                        r.len as f64 * self.nominal_s
                    ),
                );
            }
        }
        // Union of stuck sample ranges over channels.
        self.counts.stuck_samples = union_len(&mut stuck_ranges);
        for c in 0..6 {
            let st = &self.ch[c];
            if st.range_hits > 0 {
                channel_sat[c] = channel_sat[c].max(st.range_hits);
                self.counts.saturation_events += 1;
                let line = st.range_first_line;
                self.event(
                    EventKind::Saturation,
                    line,
                    0,
                    Some(c),
                    format!(
                        "{} samples at ≥ 99.9 % of the declared full scale",
                        st.range_hits
                    ),
                );
            } else if channel_sat[c] > 0 {
                let tops: Vec<(usize, usize, usize, f64)> = [&self.ch[c].max, &self.ch[c].min]
                    .iter()
                    .filter_map(|ext| {
                        ext.value
                            .filter(|v| sat_values[c].contains(v))
                            .map(|v| (ext.longest_line, ext.longest, ext.in_runs, v))
                    })
                    .collect();
                for (line, longest, n, v) in tops {
                    self.counts.saturation_events += 1;
                    self.event(
                        EventKind::Saturation,
                        line,
                        0,
                        Some(c),
                        format!(
                            "flat top at the channel's extreme {v:.6e}: {n} samples in runs, longest {longest} (clipped at full scale?)"
                        ),
                    );
                }
            }
        }
        for e in self
            .events
            .iter_mut()
            .filter(|e| e.kind == EventKind::Saturation)
        {
            e.time_s = f64::NAN;
        }
        self.counts.saturated_samples = channel_sat.iter().sum();
        // Records stuck or saturated, each counted once however many of
        // its channels are (a shock clips three axes at once).
        let mut flagged = stuck_ranges;
        let mut unranged = 0;
        for c in 0..6 {
            let st = &self.ch[c];
            let mut take = |r: &IndexRanges, n: usize| {
                if r.overflow {
                    unranged += n;
                } else {
                    flagged.extend_from_slice(&r.ranges);
                }
            };
            if st.range_hits > 0 {
                take(&st.range_runs, st.range_hits);
            }
            for ext in [&st.max, &st.min] {
                if ext.value.is_some_and(|v| sat_values[c].contains(&v)) {
                    take(&ext.runs, ext.in_runs);
                }
            }
        }
        let stuck_or_saturated_records = union_len(&mut flagged) + unranged;

        FlatRuns {
            stuck: channel_stuck,
            saturated: channel_sat,
            records: stuck_or_saturated_records,
        }
    }

    /// The intervals' statistics (from the histogram and the running
    /// moments) and the rates.
    pub(super) fn interval_stats(&self) -> (IntervalStats, Rates) {
        // Intervals.
        let hist_total: u64 = self.hist.iter().map(|&h| h as u64).sum();
        let hist_q = |q: f64| -> f64 {
            let target = (q * hist_total as f64).ceil() as u64;
            let mut acc = 0u64;
            for (i, &h) in self.hist.iter().enumerate() {
                acc += h as u64;
                if acc >= target.max(1) {
                    return (i as f64 + 0.5) * self.hist_bin_ns * 1e-9;
                }
            }
            f64::NAN
        };
        // |dt − nominal| percentile: fold the histogram around the nominal bin.
        let nominal_bin = 1000usize;
        let mut dev = vec![0u64; 4000];
        for (i, &h) in self.hist.iter().enumerate() {
            dev[i.abs_diff(nominal_bin)] += h as u64;
        }
        let overflow = (self.dt_all.n as u64).saturating_sub(hist_total);
        let target = (0.99 * self.dt_all.n as f64).ceil() as u64;
        let mut acc = 0u64;
        let mut p99 = f64::NAN;
        for (i, &h) in dev.iter().enumerate() {
            acc += h;
            if acc >= target {
                p99 = i as f64 * self.hist_bin_ns * 1e-9;
                break;
            }
        }
        if p99.is_nan() && overflow > 0 {
            p99 = self.dt_all.max - self.nominal_s;
        }
        let jitter = self.dt_regular.std();
        let intervals = IntervalStats {
            nominal_s: self.nominal_s,
            mean_s: self.dt_all.mean(),
            median_s: hist_q(0.5),
            min_s: self.dt_all.min,
            max_s: self.dt_all.max,
            jitter_rms_s: if jitter.is_finite() { jitter } else { 0.0 },
            jitter_rms_frac: if jitter.is_finite() {
                jitter / self.nominal_s
            } else {
                0.0
            },
            p99_abs_dev_s: p99,
        };
        let period = if self.reg_sxx > 0.0 {
            self.reg_sxy / self.reg_sxx
        } else {
            self.nominal_s
        };
        let true_rate = 1.0 / period;
        let nominal_rate = 1.0 / self.nominal_s;
        let round_rate = ROUND_RATES
            .iter()
            .copied()
            .find(|r| (r / true_rate - 1.0).abs() < 0.01);
        let ref_rate = round_rate.unwrap_or(nominal_rate);
        let rate_error_ppm = (true_rate / ref_rate - 1.0) * 1e6;

        let rates = Rates {
            nominal_hz: nominal_rate,
            round_hz: round_rate,
            true_hz: true_rate,
            error_ppm: rate_error_ppm,
        };
        (intervals, rates)
    }

    /// Each channel's figures over `n_acc` accepted records, with its stuck
    /// and saturated counts from `flat`.
    pub(super) fn channel_reports(&mut self, n_acc: usize, flat: &FlatRuns) -> Vec<ChannelReport> {
        // Channels.
        let mut channels = Vec::with_capacity(6);
        for c in 0..6 {
            let st = &mut self.ch[c];
            let scale = if self.format == ImuLogFormat::KfGins {
                1.0 / self.nominal_s
            } else {
                1.0
            };
            // Typical written resolution: the median step exponent.
            let total: u32 = st.step_hist.iter().sum();
            let mut acc = 0u32;
            let mut e_med = 0i32;
            for (i, &h) in st.step_hist.iter().enumerate() {
                acc += h;
                if acc * 2 >= total {
                    e_med = i as i32 - 50;
                    break;
                }
            }
            let print_step = 10f64.powi(e_med) * scale;
            // Robust noise: median |d| of d = x_k − (x_{k−1}+x_{k+1})/2, whose
            // σ is √1.5 σ_x for white noise; MAD → σ by 1.4826.
            let mut dd: Vec<f64> = st.second.data.iter().map(|x| x.abs()).collect();
            let mad = quantile(&mut dd, 0.5);
            let noise_sd = 1.4826 * mad / 1.5f64.sqrt();
            let rounding = print_step / 12f64.sqrt();
            let quant = quantization_step(&st.diffs.data);
            channels.push(ChannelReport {
                name: CHANNELS[c],
                unit: if c < 3 { "rad/s" } else { "m/s^2" },
                mean: st.moments.mean(),
                std: st.moments.std(),
                min: st.moments.min,
                max: st.moments.max,
                repeat_fraction: st.repeats as f64 / (n_acc - 1) as f64,
                quantization_step: quant,
                min_significant_digits: if st.min_sig == u8::MAX { 0 } else { st.min_sig },
                typical_significant_digits: {
                    let total: u32 = st.sig_hist.iter().sum();
                    let mut acc = 0;
                    st.sig_hist
                        .iter()
                        .position(|&h| {
                            acc += h;
                            total > 0 && acc * 2 >= total
                        })
                        .unwrap_or(0) as u8
                },
                print_step,
                noise_sd,
                rounding_to_noise: if noise_sd > 0.0 {
                    rounding / noise_sd
                } else {
                    f64::INFINITY
                },
                stuck_segments: flat.stuck[c],
                saturated_samples: flat.saturated[c],
                spikes: st.spikes,
            });
        }

        channels
    }

    /// The static segments found, and the Allan deviation of the best one.
    pub(super) fn static_and_allan(&mut self) -> (Vec<StaticSegment>, Option<AllanReport>) {
        // Static segments and Allan deviation.
        let mut static_segments = Vec::new();
        let mut allan = None;
        if let Some(mut s) = self.statics.take() {
            s.finalize();
            static_segments = s.segments.clone();
            if let Some((seg, data, decim)) = s.best.take() {
                let tau0 = self.nominal_s * decim as f64;
                let mut chans = Vec::new();
                for c in 0..6 {
                    let y: Vec<f64> = data.iter().map(|x| x[c]).collect();
                    let curve = overlapping_adev(&y, tau0);
                    // Correlated short-τ noise (e.g. increments made by the
                    // trapezoid from white rates: lag-1 0.5) bends the first
                    // points below the white-noise line; the fit then uses
                    // τ ≥ 16 τ0 only (the bend is then < 2 %: σ²(m) ∝ 2m − 3/2).
                    let rho1 = lag_corr(&y, 1);
                    let fit = if rho1.abs() > 0.2 {
                        let tail: Vec<AllanPoint> = curve
                            .iter()
                            .copied()
                            .filter(|p| p.tau_s >= 15.9 * tau0)
                            .collect();
                        fit_noise(&tail)
                    } else {
                        fit_noise(&curve)
                    };
                    // The floor is resolved when the minimum lies inside the
                    // curve, not at its longest τ.
                    let resolved = curve
                        .last()
                        .is_some_and(|l| fit.bias_instability_tau_s < 0.9 * l.tau_s);
                    let (rw_k, bi_k) = if c < 3 {
                        (60.0f64.to_degrees(), 3600.0f64.to_degrees())
                    } else {
                        (60.0, 1e5)
                    };
                    chans.push(AllanChannel {
                        name: CHANNELS[c],
                        random_walk: fit.random_walk,
                        random_walk_display: fit.random_walk * rw_k,
                        bias_instability: fit.bias_instability,
                        bias_instability_display: fit.bias_instability * bi_k,
                        bias_instability_tau_s: fit.bias_instability_tau_s,
                        bias_instability_resolved: resolved,
                        lag1_correlation: rho1,
                        lag2_correlation: lag_corr(&y, 2),
                        curve,
                    });
                }
                allan = Some(AllanReport {
                    segment: seg,
                    tau0_s: tau0,
                    channels: chans,
                });
            }
        }
        (static_segments, allan)
    }
}
