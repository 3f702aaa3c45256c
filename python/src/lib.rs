//! The native half of the `navsync` Python package: thin calls into the
//! navsync library, the GIL released while they run. Results cross as JSON
//! text (summaries) or file paths (solutions); `navsync/__init__.py` turns
//! them into dicts, NumPy arrays and pandas DataFrames.

use std::path::{Path, PathBuf};

use navsync::Diagnostics;
use navsync::fusion::TimeOffsetOptions;
use navsync::io::config::KfGinsConfig;
use navsync::pipeline::{FuseOptions, OutageSchedule, SmoothOptions};
use navsync::sim::Simulation;
use navsync::sim::scenario::{Scenario, base_layer, parse_override, set_path};
use navsync::timing::file::{sync_file, write_kfgins_config};
use navsync::timing::{SyncConfig, SyncMode};
use navsync_report::drive::{DriveOptions, process_drive};
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
    if let Some(d) = duration_s {
        if !(d.is_finite() && d > 0.0) {
            return Err(PyValueError::new_err(format!(
                "duration_s must be a positive number, not {d}"
            )));
        }
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
            if !(period_s > 0.0 && len_s > 0.0 && len_s < period_s && first_s >= 0.0) {
                return Err(PyValueError::new_err(
                    "outages=(period_s, len_s, first_s) needs 0 < len_s < period_s and first_s >= 0",
                ));
            }
            Some(OutageSchedule {
                period_s,
                len_s,
                first_s,
            })
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

// The streaming Navigator (`navsync::navigator::Navigator`: push_gnss,
// push_imu, finish with a sink) is being written in the core library; its
// binding goes here, as a `#[pyclass] Navigator`, once it lands.

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("NavsyncError", m.py().get_type::<NavsyncError>())?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(sync, m)?)?;
    m.add_function(wrap_pyfunction!(fuse, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(process_drive_json, m)?)?;
    m.add_function(wrap_pyfunction!(read_nav_bytes, m)?)?;
    Ok(())
}
