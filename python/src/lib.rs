//! The native half of the `navsync` Python package: thin calls into the
//! navsync library, the GIL released while they run. Results cross as JSON
//! text (summaries) or file paths (solutions); `navsync/__init__.py` turns
//! them into dicts, NumPy arrays and pandas DataFrames.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use navsync::Diagnostics;
use navsync::GpsTime;
use navsync::earth::Geodetic;
use navsync::filter::gnss::GnssFix;
use navsync::fusion::TimeOffsetOptions;
use navsync::ins::{ImuErrors, ImuSample, NavState};
use navsync::io::config::KfGinsConfig;
use navsync::navigator::{NavSink, Navigator, NullSink, Step};
use navsync::pipeline::{
    FuseOptions, OutageSchedule, SmoothOptions, batch_navigator, fusion_config,
};
use navsync::timing::file::{sync_file, write_kfgins_config};
use navsync::timing::{SyncConfig, SyncMode};
use navsync_report::drive::{DriveOptions, process_drive};
use navsync_sim::Simulation;
use navsync_sim::scenario::{Scenario, base_layer, parse_override, set_path};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;

create_exception!(
    _native,
    NavsyncError,
    PyException,
    "An error of the navsync library: the message names the file and line, or the setting, at fault."
);

fn py_err(e: navsync::Error) -> PyErr {
    NavsyncError::new_err(e.to_string())
}

fn json<T: serde::Serialize>(v: &T) -> PyResult<String> {
    serde_json::to_string(v).map_err(|e| NavsyncError::new_err(e.to_string()))
}

/// The version of the navsync library this module was built from.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

/// Simulates a drive into `output_dir`; returns the simulator's report (JSON).
/// Whether file readers and writers of later runs in this process get their
/// own threads (the default) or run inline: one run, one core.
#[pyfunction]
fn set_io_threads(enabled: bool) {
    navsync::stage::set_io_threads(enabled);
}

/// The current choice of [`set_io_threads`].
#[pyfunction]
fn io_threads() -> bool {
    navsync::stage::io_threads()
}

#[pyfunction]
#[pyo3(signature = (output_dir, scenario="demo", seed=None, duration_s=None, imu_grade=None, overrides=Vec::new()))]
fn simulate(
    py: Python<'_>,
    output_dir: PathBuf,
    scenario: &str,
    seed: Option<u64>,
    duration_s: Option<f64>,
    imu_grade: Option<String>,
    overrides: Vec<String>,
) -> PyResult<String> {
    if let Some(d) = duration_s
        && !(d.is_finite() && d > 0.0)
    {
        return Err(PyValueError::new_err(format!(
            "duration_s must be a positive number, not {d}"
        )));
    }
    let scenario = scenario.to_string();
    let report = py.detach(move || -> Result<_, navsync::Error> {
        let mut layer = base_layer(&scenario)?;
        if let Some(s) = seed {
            set_path(&mut layer, "seed", serde_json::json!(s))?;
        }
        if let Some(d) = duration_s {
            set_path(&mut layer, "duration_s", serde_json::json!(d))?;
        }
        if let Some(g) = imu_grade {
            set_path(&mut layer, "imu.grade", serde_json::json!(g))?;
        }
        for o in &overrides {
            let (k, v) = parse_override(o)?;
            set_path(&mut layer, &k, v)?;
        }
        let sim = Simulation::new(Scenario::from_layer(layer)?)?;
        let argv = vec![format!("navsync (python) simulate --scenario {scenario}")];
        sim.run(&output_dir, &argv, &mut |_| {})
    });
    json(&report.map_err(py_err)?)
}

/// Synchronizes a rig log into `output_dir`; returns sync_report.json's text.
#[pyfunction]
#[pyo3(signature = (rig, output_dir, mode="auto", causal=false, truth=None, kfgins_template=None))]
fn sync(
    py: Python<'_>,
    rig: PathBuf,
    output_dir: PathBuf,
    mode: &str,
    causal: bool,
    truth: Option<PathBuf>,
    kfgins_template: Option<PathBuf>,
) -> PyResult<String> {
    let mode = match mode {
        "auto" => SyncMode::Auto,
        "hw" => SyncMode::Hw,
        "hybrid" => SyncMode::Hybrid,
        "sw" => SyncMode::Sw,
        m => {
            return Err(PyValueError::new_err(format!(
                "mode '{m}': expected auto, hw, hybrid or sw"
            )));
        }
    };
    let summary = py.detach(move || -> Result<_, navsync::Error> {
        let cfg = SyncConfig {
            mode,
            causal,
            source: rig.display().to_string(),
            ..SyncConfig::default()
        };
        let s = sync_file(&rig, &output_dir, cfg, None, truth.as_deref())?;
        if let Some(t) = &kfgins_template {
            write_kfgins_config(t, &output_dir, &s.report)?;
        }
        Ok(s)
    });
    json(&summary.map_err(py_err)?.report)
}

/// Fuses a KF-GINS configuration's data into `output_dir` (as `navsync
/// fuse --config`); returns summary.json's text.
#[pyfunction]
#[pyo3(signature = (config, output_dir=None, smooth=false, estimate_time_offset=false, zupt=false, align=false, outages=None, imu_path=None, gnss_path=None, week=0))]
#[allow(clippy::too_many_arguments)]
fn fuse(
    py: Python<'_>,
    config: PathBuf,
    output_dir: Option<PathBuf>,
    smooth: bool,
    estimate_time_offset: bool,
    zupt: bool,
    align: bool,
    outages: Option<(f64, f64, f64)>,
    imu_path: Option<PathBuf>,
    gnss_path: Option<PathBuf>,
    week: i64,
) -> PyResult<String> {
    let outages = match outages {
        Some((period_s, len_s, first_s)) => {
            let o = OutageSchedule {
                period_s,
                len_s,
                first_s,
            };
            o.validate().map_err(PyValueError::new_err)?;
            Some(o)
        }
        None => None,
    };
    let summary = py.detach(move || -> Result<_, navsync::Error> {
        let mut notes = Diagnostics::default();
        let mut cfg = KfGinsConfig::load(&config, &mut notes)?;
        if let Some(p) = imu_path {
            cfg.imu_path = p;
        }
        if let Some(p) = gnss_path {
            cfg.gnss_path = p;
        }
        let out = output_dir.unwrap_or_else(|| cfg.output_path.clone());
        let opts = FuseOptions {
            output_dir: Some(out.clone()),
            outages,
            week,
            time_offset: estimate_time_offset.then_some(TimeOffsetOptions::default()),
            smooth: smooth.then_some(SmoothOptions::default()),
            align: align.then_some(navsync::align::AlignOptions::default()),
            standstill: zupt.then_some(Default::default()),
            ..FuseOptions::default()
        };
        opts.validate()?;
        navsync_report::drive::fuse(&cfg, &opts, &out)
    });
    json(&summary.map_err(py_err)?)
}

/// Scores a solution against a reference (as `navsync eval`); returns the
/// report's JSON text.
#[pyfunction]
#[pyo3(signature = (truth, nav, outages=""))]
fn evaluate(py: Python<'_>, truth: PathBuf, nav: PathBuf, outages: &str) -> PyResult<String> {
    let outages = navsync::eval::parse_outages(outages, 0).map_err(py_err)?;
    let report = py.detach(move || {
        let mut diag = Diagnostics::default();
        navsync::eval::eval_files(&truth, &nav, &outages, &mut diag)
    });
    json(&report.map_err(py_err)?)
}

/// One drive end to end (sync → fuse → smooth → eval → report); returns
/// its row as JSON text. Failures are in the row, not raised.
#[pyfunction]
#[pyo3(signature = (input_dir, output_dir, smooth=true, estimate_time_offset=true, html=true))]
fn process_drive_json(
    py: Python<'_>,
    input_dir: PathBuf,
    output_dir: PathBuf,
    smooth: bool,
    estimate_time_offset: bool,
    html: bool,
) -> PyResult<String> {
    let opts = DriveOptions {
        smooth,
        estimate_time_offset,
        html,
    };
    let row = py.detach(move || process_drive(&input_dir, &output_dir, &opts));
    json(&row)
}

/// Reads an 11-column navigation file (KF-GINS `navresult.nav`, `truth.nav`):
/// returns (raw f64 little-endian bytes, columns), refusing short or
/// non-numeric lines with file:line.
#[pyfunction]
fn read_nav_bytes(py: Python<'_>, path: PathBuf) -> PyResult<(Vec<u8>, usize)> {
    let data = py.detach(move || read_table(&path, 11));
    let data = data.map_err(py_err)?;
    let mut bytes = Vec::with_capacity(data.len() * 8);
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    Ok((bytes, 11))
}

fn read_table(path: &Path, cols: usize) -> Result<Vec<f64>, navsync::Error> {
    let text = std::fs::read_to_string(path).map_err(|e| navsync::Error::io(path, e))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let start = out.len();
        for f in line.split_ascii_whitespace().take(cols) {
            let v: f64 = f.parse().map_err(|_| {
                navsync::Error::parse(path, i + 1, format!("'{f}' is not a number"))
            })?;
            out.push(v);
        }
        if out.len() - start != cols {
            return Err(navsync::Error::parse(
                path,
                i + 1,
                format!("expected {cols} columns, found {}", out.len() - start),
            ));
        }
    }
    Ok(out)
}

/// Collects the solutions of a stream as rows of
/// `sow_s lat_deg lon_deg h_m vn_mps ve_mps vd_mps roll_deg pitch_deg yaw_deg`.
#[derive(Default)]
struct RowSink {
    rows: Vec<f64>,
}

impl NavSink for RowSink {
    fn nav(&mut self, nav: &NavState, _imu: &ImuErrors) -> Result<(), navsync::Error> {
        let e = nav.euler().to_deg();
        self.rows.extend_from_slice(&[
            nav.time.sow(),
            nav.pos.lat_rad.to_degrees(),
            nav.pos.lon_rad.to_degrees(),
            nav.pos.h_m,
            nav.vel.x,
            nav.vel.y,
            nav.vel.z,
            e[0],
            e[1],
            e[2],
        ]);
        Ok(())
    }
}

fn f64s_from_le(bytes: &[u8], cols: usize, what: &str) -> PyResult<Vec<f64>> {
    if !bytes.len().is_multiple_of(8 * cols) {
        return Err(PyValueError::new_err(format!(
            "{what}: expected rows of {cols} float64 values, got {} bytes",
            bytes.len()
        )));
    }
    let v: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect();
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{what}: row {} column {} is not a finite number",
            i / cols,
            i % cols
        )));
    }
    Ok(v)
}

fn to_le_bytes(v: &[f64]) -> Vec<u8> {
    let mut out = Vec::with_capacity(v.len() * 8);
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
    out
}

/// The streaming navigator (`navsync::navigator::Navigator`) over a KF-GINS
/// configuration: GNSS fixes and IMU increments pushed in blocks, the
/// solutions returned at every IMU epoch.
#[pyclass(unsendable)]
struct NativeNavigator {
    nav: Option<Navigator>,
    week: i64,
}

impl NativeNavigator {
    fn nav(&mut self) -> PyResult<&mut Navigator> {
        self.nav
            .as_mut()
            .ok_or_else(|| NavsyncError::new_err("the navigator has finished"))
    }
}

#[pymethods]
impl NativeNavigator {
    #[new]
    #[pyo3(signature = (config, week=0))]
    fn new(config: PathBuf, week: i64) -> PyResult<Self> {
        let cfg = KfGinsConfig::load(&config, &mut Diagnostics::with_cap(10)).map_err(py_err)?;
        let opts = FuseOptions {
            week,
            ..FuseOptions::default()
        };
        let nav = batch_navigator(fusion_config(&cfg, &opts), &opts).map_err(py_err)?;
        Ok(NativeNavigator {
            nav: Some(nav),
            week,
        })
    }

    /// Fixes as rows `sow_s lat_deg lon_deg h_m sd_n_m sd_e_m sd_d_m`.
    fn push_gnss(&mut self, rows: &[u8]) -> PyResult<usize> {
        let v = f64s_from_le(rows, 7, "GNSS fixes")?;
        let week = self.week;
        let nav = self.nav()?;
        for r in v.chunks_exact(7) {
            if !(r[4] > 0.0 && r[5] > 0.0 && r[6] > 0.0) {
                return Err(PyValueError::new_err(format!(
                    "GNSS fix at {} s: σ must be positive",
                    r[0]
                )));
            }
            nav.push_gnss(GnssFix {
                time: GpsTime::from_week_sow(week, r[0]),
                pos: Geodetic::from_deg(r[1], r[2], r[3]),
                pos_sd: Vector3::new(r[4], r[5], r[6]),
                vel: None,
                vel_sd: None,
            });
        }
        Ok(v.len() / 7)
    }

    /// IMU increments as rows `sow_s dθx dθy dθz (rad) dvx dvy dvz (m/s)`
    /// (FRD); returns the solutions as little-endian float64 rows of 10.
    fn push_imu(&mut self, py: Python<'_>, rows: &[u8]) -> PyResult<Vec<u8>> {
        let v = f64s_from_le(rows, 7, "IMU increments")?;
        let week = self.week;
        let nav = self.nav()?;
        let out = py.detach(move || -> Result<Vec<f64>, navsync::Error> {
            let mut sink = RowSink::default();
            for r in v.chunks_exact(7) {
                let s = ImuSample {
                    time: GpsTime::from_week_sow(week, r[0]),
                    dtheta: Vector3::new(r[1], r[2], r[3]),
                    dvel: Vector3::new(r[4], r[5], r[6]),
                    odo_speed: None,
                };
                if let Step::Ended = nav.push_imu(&s, &mut sink)? {
                    break;
                }
            }
            Ok(sink.rows)
        });
        Ok(to_le_bytes(&out.map_err(py_err)?))
    }

    /// Ends the stream: a JSON summary (fixes weighed, withheld, statistics).
    fn finish(&mut self) -> PyResult<String> {
        let mut nav = self
            .nav
            .take()
            .ok_or_else(|| NavsyncError::new_err("the navigator has finished"))?;
        let end = nav.finish(&mut NullSink).map_err(py_err)?;
        let stats = nav.fusion().stats();
        json(&serde_json::json!({
            "fixes_weighed": end.fix_records.len(),
            "fixes_withheld": end.counts.fixes_withheld,
            "fixes_outside_run": end.counts.fixes_outside,
            "first_sow_s": end.counts.first_epoch.map(|t| t.sow()),
            "last_sow_s": end.counts.last_epoch.map(|t| t.sow()),
            "stats": stats,
            "notes": end.diagnostics,
        }))
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("NavsyncError", m.py().get_type::<NavsyncError>())?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(set_io_threads, m)?)?;
    m.add_function(wrap_pyfunction!(io_threads, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(sync, m)?)?;
    m.add_function(wrap_pyfunction!(fuse, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(process_drive_json, m)?)?;
    m.add_function(wrap_pyfunction!(read_nav_bytes, m)?)?;
    m.add_class::<NativeNavigator>()?;
    Ok(())
}
