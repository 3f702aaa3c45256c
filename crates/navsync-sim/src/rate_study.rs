//! The lowest IMU rate that costs no accuracy (seed 001 §1.3.3).
//!
//! Seed 001 §1.3.3: decimate (by averaging) to candidate rates, simulate
//! GNSS outages, and compare the drift statistics; the lowest rate whose
//! drift has not clearly grown is the one to use (vehicles: 5–10 Hz;
//! multirotors: 20–25 Hz, per the seed). For each rate the configuration's
//! IMU file is decimated ([`IncrementDecimator`], accumulation, windows on
//! multiples of the output period), fused by [`pipeline::run`] with GNSS
//! withheld on the outage schedule (60 s every 180 s, the KF-GINS/i2Nav
//! protocol), and every output epoch is scored against a truth file; the
//! drift figure is the RMS over outages of the maximum horizontal error in
//! each (Niu et al. 2010, as in [`navsync::eval`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use navsync::error::{Diagnostics, Error};
use navsync::eval::{EpochError, Evaluator, TruthScorer};
use navsync::imu::decimate::{DecRate, DecimationMethod, IncrementDecimator};
use navsync::ins::{ImuErrors, NavState};
use navsync::io::config::KfGinsConfig;
use navsync::io::kfgins::{ImuReader, TextWriter, format_imu_line};
use navsync::pipeline::{self, FuseOptions, NavSink, OutageSchedule};
use navsync::time::GpsTime;

/// What to study.
#[derive(Clone, Debug)]
pub struct RateStudyOptions {
    /// Output rates (Hz), each an integer divisor of the input rate.
    pub rates_hz: Vec<f64>,
    pub method: DecimationMethod,
    pub outages: OutageSchedule,
    /// Reference trajectory (11-column nav format).
    pub truth: PathBuf,
    /// Fusion options (outages and output are set by the study).
    pub fuse: FuseOptions,
    /// Where decimated files are written.
    pub work_dir: PathBuf,
    /// Keep the decimated files.
    pub keep_files: bool,
}

/// One rate's result.
#[derive(Clone, Debug, Serialize)]
pub struct RateStudyRow {
    pub rate_hz: f64,
    /// ADIS16465-style register value: input / (DEC_RATE + 1) = rate.
    pub dec_rate: u32,
    pub imu_samples: usize,
    pub outages: usize,
    /// RMS over outages of the maximum horizontal drift (m).
    pub rms_max_horizontal_m: f64,
    pub worst_horizontal_m: f64,
    pub rms_max_3d_m: f64,
    /// Horizontal position RMS over the whole run (m).
    pub horizontal_rms_m: f64,
    pub yaw_rms_deg: f64,
    pub run_time_s: f64,
    /// The decimated file, when kept.
    pub imu_file: Option<String>,
}

/// Scores every navigation epoch against the truth (kept in memory; the
/// outage windows are known only after the run).
struct EvalSink {
    truth: TruthScorer,
    errors: Vec<EpochError>,
}

impl NavSink for EvalSink {
    fn nav(&mut self, nav: &NavState, _imu: &ImuErrors) -> Result<(), Error> {
        if let Some(e) = self.truth.score(nav)? {
            self.errors.push(e);
        }
        Ok(())
    }
}

/// Writes the configuration's IMU decimated by `dec` to `out`; returns the
/// number of samples written.
pub fn decimate_file(
    input: &Path,
    out: &Path,
    input_rate_hz: f64,
    dec: DecRate,
    method: DecimationMethod,
    week: i64,
    diag: &mut Diagnostics,
) -> Result<usize, Error> {
    let mut r = ImuReader::open(input, week)?;
    let mut d = IncrementDecimator::new(dec, method, Some(input_rate_hz), true, 1.5);
    let mut w = TextWriter::create(out)?;
    let mut buf = Vec::with_capacity(1 << 20);
    let mut n = 0;
    let mut put = |s: navsync::ins::ImuSample, buf: &mut Vec<u8>| {
        format_imu_line(buf, &s);
        n += 1;
    };
    while let Some(s) = r.next_sample(diag)? {
        for o in d.push(&s) {
            put(o, &mut buf);
        }
        if buf.len() > (1 << 20) - 512 {
            w.write(&buf)?;
            buf.clear();
        }
    }
    if let Some(o) = d.flush() {
        put(o, &mut buf);
    }
    w.write(&buf)?;
    w.finish()?;
    Ok(n)
}

/// Runs the study; `progress(k, fraction)` reports rate `k`'s progress.
pub fn rate_study(
    cfg: &KfGinsConfig,
    opts: &RateStudyOptions,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Vec<RateStudyRow>, Error> {
    let input = cfg.imu_rate_hz;
    let decs = opts
        .rates_hz
        .iter()
        .map(|&r| DecRate::from_rates(input, r))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Error::config(&cfg.path, format!("imudatarate {input} Hz: {e}")))?;
    std::fs::create_dir_all(&opts.work_dir).map_err(|e| Error::io(&opts.work_dir, e))?;
    let mut rows = Vec::new();
    for (k, (&rate, &dec)) in opts.rates_hz.iter().zip(&decs).enumerate() {
        let started = Instant::now();
        let mut diag = Diagnostics::default();
        let (path, written) = if dec.factor() == 1 && opts.method == DecimationMethod::Average {
            (cfg.imu_path.clone(), false)
        } else {
            let name = format!(
                "imu_{}hz_{}.txt",
                rate,
                match opts.method {
                    DecimationMethod::Average => "average",
                    DecimationMethod::Point => "point",
                }
            );
            let p = opts.work_dir.join(name);
            decimate_file(
                &cfg.imu_path,
                &p,
                input,
                dec,
                opts.method,
                opts.fuse.week,
                &mut diag,
            )?;
            (p, true)
        };
        let mut c = cfg.clone();
        c.imu_path = path.clone();
        c.imu_rate_hz = dec.output_rate_hz(input);
        let mut fo = opts.fuse.clone();
        fo.outages = Some(opts.outages);
        fo.dry_run = true;
        let mut sink = EvalSink {
            truth: TruthScorer::open(&opts.truth)?,
            errors: Vec::new(),
        };
        let summary = pipeline::run(&c, &fo, &mut sink, &mut |f| progress(k, f))?;
        let t0 = GpsTime::from_week_sow(fo.week, summary.start_sow);
        let t1 = GpsTime::from_week_sow(fo.week, summary.end_sow);
        // The windows the pipeline withheld GNSS in (same schedule, same t0).
        let mut ev = Evaluator::new(&opts.outages.windows(t0, t1));
        for e in &sink.errors {
            ev.push(e);
        }
        let rep = ev.finish();
        if rep.epochs_compared == 0 {
            return Err(Error::NoData {
                path: opts.truth.clone(),
                msg: format!("no navigation epoch at {rate} Hz overlaps the truth"),
            });
        }
        let keep = opts.keep_files || !written;
        if !keep {
            let _ = std::fs::remove_file(&path);
        }
        rows.push(RateStudyRow {
            rate_hz: rate,
            dec_rate: dec.0,
            imu_samples: summary.stats.imu_samples,
            outages: rep.outages.len(),
            rms_max_horizontal_m: rep.outage_rms_max_horizontal_m.unwrap_or(f64::NAN),
            worst_horizontal_m: rep.outage_worst_horizontal_m.unwrap_or(f64::NAN),
            rms_max_3d_m: rep.outage_rms_max_3d_m.unwrap_or(f64::NAN),
            horizontal_rms_m: rep.pos_horizontal_m.rms,
            yaw_rms_deg: rep.yaw_deg.rms,
            run_time_s: started.elapsed().as_secs_f64(),
            imu_file: keep.then(|| path.display().to_string()),
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use navsync::earth;
    use navsync::ins::ImuSample;
    use std::fmt::Write as _;

    /// A vehicle at rest, level, facing north: exact increments (Earth rate
    /// and gravity), 1 Hz GNSS and truth at the same point.
    fn static_scenario(dir: &Path, seconds: i64) -> KfGinsConfig {
        std::fs::create_dir_all(dir).unwrap();
        let (lat, lon, h) = (30.0f64, 114.0, 20.0);
        let (s, c) = lat.to_radians().sin_cos();
        let w = earth::omega_ie_n(s, c);
        let g = earth::gravity(s, h);
        let dt = 0.005;
        let mut imu = Vec::new();
        for k in 1..=(seconds * 200) {
            let t = GpsTime::from_ns(100_000 * 1_000_000_000 + k * 5_000_000);
            format_imu_line(
                &mut imu,
                &ImuSample {
                    time: t,
                    dtheta: w * dt,
                    dvel: Vector3::new(0.0, 0.0, -g * dt),
                    odo_speed: None,
                },
            );
        }
        std::fs::write(dir.join("imu.txt"), imu).unwrap();
        let (mut gnss, mut truth) = (String::new(), String::new());
        for k in 1..=seconds {
            let _ = writeln!(gnss, "{}.0 {lat} {lon} {h} 0.02 0.02 0.03", 100_000 + k);
            let _ = writeln!(truth, "0 {}.0 {lat} {lon} {h} 0 0 0 0 0 0", 100_000 + k - 1);
        }
        std::fs::write(dir.join("gnss.txt"), gnss).unwrap();
        std::fs::write(dir.join("truth.nav"), truth).unwrap();
        let yaml = format!(
            r#"
imupath: "{d}/imu.txt"
gnsspath: "{d}/gnss.txt"
outputpath: "{d}/out"
imudatalen: 7
imudatarate: 200
starttime: 100000.005
endtime: -1
initpos: [ {lat}, {lon}, {h} ]
initvel: [ 0.0, 0.0, 0.0 ]
initatt: [ 0.0, 0.0, 0.0 ]
initgyrbias: [ 0, 0, 0 ]
initaccbias: [ 0, 0, 0 ]
initgyrscale: [ 0, 0, 0 ]
initaccscale: [ 0, 0, 0 ]
initposstd: [ 0.05, 0.05, 0.1 ]
initvelstd: [ 0.05, 0.05, 0.05 ]
initattstd: [ 0.1, 0.1, 0.5 ]
imunoise:
  arw: [ 0.15, 0.15, 0.15 ]
  vrw: [ 0.04, 0.04, 0.04 ]
  gbstd: [ 2.0, 2.0, 2.0 ]
  abstd: [ 3.6, 3.6, 3.6 ]
  gsstd: [ 500.0, 500.0, 500.0 ]
  asstd: [ 500.0, 500.0, 500.0 ]
  corrtime: 1.0
antlever: [ 0.0, 0.0, 0.0 ]
"#,
            d = dir.display()
        );
        let mut diag = Diagnostics::default();
        KfGinsConfig::parse(&yaml, &dir.join("cfg.yaml"), &mut diag).unwrap()
    }

    #[test]
    fn decimated_files_keep_every_increment() {
        let dir = navsync::testfiles::TestDir::new("ratestudy-dec");
        let cfg = static_scenario(&dir, 10);
        let out = dir.join("imu25.txt");
        let mut diag = Diagnostics::default();
        let n = decimate_file(
            &cfg.imu_path,
            &out,
            200.0,
            DecRate(7),
            DecimationMethod::Average,
            0,
            &mut diag,
        )
        .unwrap();
        assert_eq!(n, 250);
        let mut r = ImuReader::open(&out, 0).unwrap();
        let first = r.next_sample(&mut diag).unwrap().unwrap();
        // The first window (100000.000, 100000.040] holds 8 increments.
        assert_eq!(
            first.time,
            GpsTime::from_ns(100_000 * 1_000_000_000 + 40_000_000)
        );
        let g = earth::gravity(30f64.to_radians().sin(), 20.0);
        assert!((first.dvel.z + g * 0.04).abs() < 1e-15);
    }

    #[test]
    fn study_of_a_vehicle_at_rest_shows_no_drift_at_any_rate() {
        // Exact, error-free increments of a vehicle at rest: whatever the
        // rate, the INS stays put within the filter's tiny corrections, so
        // drift over the outages must stay at the mm level everywhere.
        let dir = navsync::testfiles::TestDir::new("ratestudy");
        let cfg = static_scenario(&dir, 240);
        let opts = RateStudyOptions {
            rates_hz: vec![200.0, 50.0, 10.0],
            method: DecimationMethod::Average,
            outages: OutageSchedule {
                period_s: 100.0,
                len_s: 30.0,
                first_s: 50.0,
            },
            truth: dir.join("truth.nav"),
            fuse: FuseOptions::default(),
            work_dir: dir.join("work"),
            keep_files: false,
        };
        let rows = rate_study(&cfg, &opts, &mut |_, _| {}).unwrap();
        assert_eq!(
            rows.iter().map(|r| r.dec_rate).collect::<Vec<_>>(),
            vec![0, 3, 19]
        );
        for r in &rows {
            assert_eq!(r.outages, 2, "{r:?}");
            assert!(r.rms_max_horizontal_m < 0.01, "{r:?}");
        }
        assert!(rows[2].imu_samples < rows[0].imu_samples / 19);
        // Bad rates are refused with the reason.
        let bad = RateStudyOptions {
            rates_hz: vec![30.0],
            ..opts
        };
        let err = rate_study(&cfg, &bad, &mut |_, _| {})
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a whole number"), "{err}");
    }
}
