//! The live loop measured on pseudo-terminals at real rate (no hardware):
//! a [`Replay`] writes a 200 Hz IMU and a 10 Hz receiver into PTYs and
//! injects PPS edges (with a gap), [`crate::live::run`] reads them, and the
//! figures of the issue come out: samples lost, arrival → solution latency,
//! CPU time, stamp errors against the replay's truth, holdover and relock.

use std::io;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use nalgebra::Vector3;
use navsync::attitude::Euler;
use navsync::filter::{ImuNoise, InitialStd};
use navsync::fusion::{FusionConfig, NavOutput};
use navsync::ins::NavState;
use navsync::timing::LockState;
use serde::Serialize;

use crate::files::FileSink;
use crate::live::{
    self, LiveConfig, LiveReport, LiveSink, LiveStatus, NavInfo, PortConfig, PpsInput, SourceId,
};
use crate::pps;
use crate::replay::{GnssKind, Replay, ReplayConfig, imu_truth};

/// Settings of a self-test.
#[derive(Clone, Debug)]
pub struct SelftestConfig {
    pub replay: ReplayConfig,
    /// Filter settings; `None`: a built-in MEMS (ADIS16465-class) setup.
    pub fusion: Option<FusionConfig>,
    /// Print the status line every second.
    pub verbose: bool,
    /// Also write the solution as KF-GINS files here.
    pub output: Option<std::path::PathBuf>,
    /// `--record`: the received records as a rig log.
    pub record: Option<std::path::PathBuf>,
    /// `--record-gnss`: the receiver's raw bytes.
    pub record_gnss: Option<std::path::PathBuf>,
    /// [`LiveConfig::imu_lookahead_s`].
    pub imu_lookahead_s: f64,
    /// [`LiveConfig::hdt_sd_deg`].
    pub hdt_sd_deg: f64,
}

impl SelftestConfig {
    /// `duration_s` of data with PPS removed for `gap_len_s` from `gap_start_s`.
    pub fn new(duration_s: f64, gap_start_s: f64, gap_len_s: f64) -> Self {
        SelftestConfig {
            replay: ReplayConfig {
                duration_s,
                pps_gap: (gap_len_s > 0.0).then_some((gap_start_s, gap_len_s)),
                ..Default::default()
            },
            fusion: None,
            verbose: false,
            output: None,
            record: None,
            record_gnss: None,
            imu_lookahead_s: live::DEFAULT_IMU_LOOKAHEAD_S,
            hdt_sd_deg: crate::gnss::DEFAULT_HDT_SD_DEG,
        }
    }
}

/// Stamp errors against the replay's truth (µs).
#[derive(Clone, Debug, Default, Serialize)]
pub struct StampErrors {
    pub compared: u64,
    pub rms_us: f64,
    pub max_abs_us: f64,
    pub holdover_compared: u64,
    pub holdover_max_abs_us: f64,
}

/// The figures of a self-test.
#[derive(Clone, Debug, Serialize)]
pub struct SelftestReport {
    pub duration_s: f64,
    pub imu_written: u64,
    pub imu_received: u64,
    pub imu_stamped: u64,
    /// Written but never stamped, plus gaps the timing found.
    pub samples_lost: u64,
    pub solutions: u64,
    pub gnss_epochs_written: u64,
    pub gnss_fixes_received: u64,
    pub gnss_fixes_fused: u64,
    pub pps_injected: u64,
    pub pps_gap: Option<(f64, f64)>,
    pub latency_median_us: Option<f64>,
    pub latency_p99_us: Option<f64>,
    pub latency_max_us: Option<f64>,
    /// CPU time of the live threads (process minus the replay writer), % of one core.
    pub cpu_percent: f64,
    pub cpu_s: f64,
    pub replay_cpu_s: f64,
    /// Worst lateness of the replay writer against its schedule (ms).
    pub replay_max_late_ms: f64,
    /// Seconds into the run when the clock entered holdover and relocked.
    pub holdover_at_s: Vec<f64>,
    pub relocked_at_s: Vec<f64>,
    /// The engine's holdover spans (first and last stamp in holdover), in
    /// GPS seconds since the replay's start.
    pub holdover_spans_s: Vec<(f64, f64)>,
    pub stamp_errors: StampErrors,
    /// Largest position distance from the true position (m) after 5 s of fusion.
    pub max_pos_error_m: f64,
    /// The last solution's roll, pitch and yaw (deg; the truth is level,
    /// facing north) and its yaw σ as of the last second (deg).
    pub final_att_deg: Option<[f64; 3]>,
    pub final_yaw_sd_deg: Option<f64>,
    pub live: LiveReport,
}

/// The filter settings of the self-test: the replay's position, level,
/// heading north; ADIS16465-class MEMS noise (ARW 0.15 deg/√h, VRW
/// 0.04 m/s/√h, bias instability 2 deg/h and 3.6 mGal over 1 h, scale
/// factors 500 ppm).
pub fn builtin_fusion(r: &ReplayConfig) -> FusionConfig {
    let deg = std::f64::consts::PI / 180.0;
    let v = |x: f64| Vector3::new(x, x, x);
    let noise = ImuNoise {
        arw: v(0.15 * deg / 60.0),
        vrw: v(0.04 / 60.0),
        gyro_bias_sd: v(2.0 * deg / 3600.0),
        accel_bias_sd: v(3.6e-5),
        gyro_scale_sd: v(500e-6),
        accel_scale_sd: v(500e-6),
        corr_time_s: 3600.0,
    };
    let init_std = InitialStd {
        pos: Vector3::new(1.0, 1.0, 1.5),
        vel: v(0.1),
        att: Vector3::new(0.5 * deg, 0.5 * deg, 1.0 * deg),
        gyro_bias: noise.gyro_bias_sd,
        accel_bias: noise.accel_bias_sd,
        gyro_scale: noise.gyro_scale_sd,
        accel_scale: noise.accel_scale_sd,
    };
    let nav = NavState::new(
        r.start,
        r.pos,
        Vector3::zeros(),
        &Euler::from_deg(0.0, 0.0, 0.0),
    );
    FusionConfig::new(nav, init_std, noise, r.imu_rate_hz)
}

struct Measure<'a> {
    replay: &'a ReplayConfig,
    err: StampErrors,
    sum_sq: f64,
    first_solution: Option<u64>,
    max_pos_m: f64,
    last_att_deg: Option<[f64; 3]>,
    last_yaw_sd_deg: Option<f64>,
    verbose: bool,
    files: Option<FileSink>,
}

impl LiveSink for Measure<'_> {
    fn nav(&mut self, out: &NavOutput, info: &NavInfo) -> Result<(), navsync::Error> {
        if let Some(f) = self.files.as_mut() {
            f.nav(out)?;
        }
        let e_us = (out.nav.time - imu_truth(self.replay, info.seq)) as f64 * 1e-3;
        self.err.compared += 1;
        self.sum_sq += e_us * e_us;
        self.err.max_abs_us = self.err.max_abs_us.max(e_us.abs());
        if info.holdover {
            self.err.holdover_compared += 1;
            self.err.holdover_max_abs_us = self.err.holdover_max_abs_us.max(e_us.abs());
        }
        self.last_att_deg = Some(out.nav.euler().to_deg());
        let first = *self.first_solution.get_or_insert(info.seq);
        if info.seq > first + 5 * self.replay.imu_rate_hz as u64 {
            let p = &self.replay.pos;
            let le = navsync::earth::LocalEarth::new(p, &nalgebra::Vector3::zeros());
            let d = le.geodetic_delta_to_ned(
                out.nav.pos.lat_rad - p.lat_rad,
                out.nav.pos.lon_rad - p.lon_rad,
                out.nav.pos.h_m - p.h_m,
            );
            self.max_pos_m = self.max_pos_m.max(d.norm());
        }
        Ok(())
    }

    fn aux(&mut self, out: &NavOutput, sd: &[f64]) -> Result<(), navsync::Error> {
        // The error state's attitude (φ, θ, ψ) follows position and
        // velocity: yaw is its 9th element.
        self.last_yaw_sd_deg = sd.get(8).map(|v| v.to_degrees());
        match self.files.as_mut() {
            Some(f) => f.aux(out, sd),
            None => Ok(()),
        }
    }

    fn status(&mut self, s: &LiveStatus) {
        if self.verbose {
            println!("{}", crate::status_line(s));
        }
    }

    fn note(&mut self, source: SourceId, msg: &str) {
        if self.verbose {
            println!("  [{source}] {msg}");
        }
    }
}

/// Runs the self-test in `dir` (the PTY links are made there).
pub fn run(cfg: &SelftestConfig, dir: &Path) -> io::Result<SelftestReport> {
    std::fs::create_dir_all(dir)?;
    let r = &cfg.replay;
    let fusion = cfg.fusion.clone().unwrap_or_else(|| builtin_fusion(r));
    let (inj, src) = pps::injected();
    let replay = Replay::start(r.clone(), dir, inj, 0.5)?;
    if cfg.verbose {
        // What an outside observer needs to know what was sent when.
        println!(
            "replay: GPS {} {:.3} at host counter {} ns (CLOCK_MONOTONIC_RAW), GPS {} ppm fast",
            r.start.week(),
            r.start.sow(),
            replay.clock.host0,
            r.host_ppm
        );
    }
    let baud = 921600;
    let imu_port = PortConfig {
        path: replay.imu_port.clone(),
        baud,
    };
    let mut lc = LiveConfig::new(
        PortConfig {
            path: replay.gnss_port.clone(),
            baud,
        },
        (!r.imu_esf).then_some(imu_port),
        PpsInput::Source(Box::new(src)),
        fusion,
    );
    if r.imu_esf {
        lc.esf_tick_s = Some(1e-3);
    }
    lc.imu_rate_hz = r.imu_rate_hz;
    lc.imu_lookahead_s = cfg.imu_lookahead_s;
    lc.hdt_sd_deg = cfg.hdt_sd_deg;
    lc.reopen_interval = Duration::from_millis(200);
    lc.record = cfg.record.clone();
    lc.record_gnss = cfg.record_gnss.clone();
    // Until the writer's last line has been read.
    lc.duration = Some(Duration::from_secs_f64(r.duration_s + 0.8));
    let mut m = Measure {
        replay: r,
        err: StampErrors::default(),
        sum_sq: 0.0,
        first_solution: None,
        max_pos_m: 0.0,
        last_att_deg: None,
        last_yaw_sd_deg: None,
        verbose: cfg.verbose,
        files: cfg.output.as_deref().map(FileSink::new),
    };
    let stop = AtomicBool::new(false);
    let report = live::run(lc, &stop, &mut m);
    let stats = replay.finish(true)?;
    let report = report?;
    if let Some(f) = m.files.take() {
        f.finish().map_err(|e| io::Error::other(e.to_string()))?;
    }
    m.err.rms_us = if m.err.compared > 0 {
        (m.sum_sq / m.err.compared as f64).sqrt()
    } else {
        f64::NAN
    };
    let c = &report.counts;
    let at = |s: LockState| -> Vec<f64> {
        report
            .state_changes
            .iter()
            .filter(|c| c.state == s)
            .map(|c| c.at_s)
            .collect()
    };
    let lost = stats.imu_written.saturating_sub(c.imu_stamped) + c.imu_lost;
    let cpu_s = report.cpu_s - stats.cpu_s;
    let mut holdover_at_s = at(LockState::Holdover);
    let mut relocked_at_s = at(LockState::Locked);
    // Times relative to the replay's first second (the live clock starts
    // 0.5 s before it).
    for v in holdover_at_s.iter_mut().chain(relocked_at_s.iter_mut()) {
        *v -= 0.5;
    }
    let since_start = |w: &navsync::timing::report::WeekSow| {
        (w.week - r.start.week()) as f64 * 604_800.0 + w.sow - r.start.sow()
    };
    let holdover_spans_s = report
        .sync
        .as_ref()
        .map(|s| {
            s.holdover
                .iter()
                .map(|h| (since_start(&h.start), since_start(&h.end)))
                .collect()
        })
        .unwrap_or_default();
    Ok(SelftestReport {
        duration_s: report.duration_s,
        imu_written: stats.imu_written,
        imu_received: c.imu_lines,
        imu_stamped: c.imu_stamped,
        samples_lost: lost,
        solutions: c.solutions,
        gnss_epochs_written: stats.gnss_epochs,
        gnss_fixes_received: c.gnss_fixes,
        gnss_fixes_fused: c.gnss_fused,
        pps_injected: stats.pps_injected,
        pps_gap: r.pps_gap,
        latency_median_us: report.latency.median_us,
        latency_p99_us: report.latency.p99_us,
        latency_max_us: report.latency.max_us,
        cpu_percent: 100.0 * cpu_s / report.duration_s.max(1e-9),
        cpu_s,
        replay_cpu_s: stats.cpu_s,
        replay_max_late_ms: stats.max_late_s * 1e3,
        holdover_at_s,
        relocked_at_s,
        holdover_spans_s,
        stamp_errors: m.err,
        max_pos_error_m: m.max_pos_m,
        final_att_deg: m.last_att_deg,
        final_yaw_sd_deg: m.last_yaw_sd_deg,
        live: report,
    })
}

/// GNSS message set from its CLI name.
pub fn gnss_kind(name: &str) -> Option<GnssKind> {
    match name {
        "ubx" => Some(GnssKind::Ubx),
        "nmea" => Some(GnssKind::Nmea),
        _ => None,
    }
}
