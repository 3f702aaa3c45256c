//! A simulation scenario: the trajectory, the sensors and the rig, with
//! every parameter, as read from a user's TOML file and command-line
//! overrides on top of defaults and presets.
//!
//! Layering: defaults ← the IMU preset named by `imu.grade` (default
//! `adis16465`) ← the user's TOML file ← `--set key=value` style overrides.
//! Unknown keys are errors that name the key (and the line in a TOML
//! file), never silently ignored.

use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use super::gnss::GnssSpec;
use super::imu::{IMU_PRESETS, ImuSpec};
use super::rig::RigSpec;
use super::trajectory::{BUILTIN_SCENARIOS, Segment, VibrationSpec, builtin_segments};
use navsync::error::Error;

/// Options of the written files.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputSpec {
    /// Interval of `imu_err_truth.txt` lines (s).
    pub imu_err_interval_s: f64,
    /// Write `rig.csv` and `imu_times_truth.txt`.
    pub rig_log: bool,
    /// Error added to the initial state written into the KF-GINS
    /// configuration: NED position (m), velocity (m/s), roll/pitch/yaw (deg).
    pub init_error_pos_m: [f64; 3],
    pub init_error_vel_mps: [f64; 3],
    pub init_error_att_deg: [f64; 3],
}

impl Default for OutputSpec {
    fn default() -> Self {
        OutputSpec {
            imu_err_interval_s: 1.0,
            rig_log: true,
            init_error_pos_m: [0.0; 3],
            init_error_vel_mps: [0.0; 3],
            init_error_att_deg: [0.0; 3],
        }
    }
}

/// Everything a run needs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    /// A built-in trajectory (`test-track`, `urban`, `figure8`, `static`),
    /// used when `segments` is empty.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<String>,
    /// A user trajectory as a list of segments.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub segments: Vec<Segment>,
    /// A reference drive (KF-GINS navigation file) to fit and follow
    /// instead of built-in profiles: its first state sets the start time
    /// and origin, its span the duration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_nav: Option<String>,
    /// Seed of every error source.
    pub seed: u64,
    /// Seed of the random trajectory (`urban`).
    pub traj_seed: u64,
    /// Length of the run (s); built-in trajectories default to 600 s, user
    /// segments to their own length.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    pub gps_week: i64,
    pub start_sow: f64,
    /// Start position: latitude (deg), longitude (deg), ellipsoidal height (m).
    pub origin: [f64; 3],
    pub initial_heading_deg: f64,
    pub initial_speed_mps: f64,
    /// Roll per lateral acceleration, φ = −k·v·ψ̇ (deg per m/s²).
    pub roll_gain_deg_per_mps2: f64,
    pub vibration: VibrationSpec,
    pub imu: ImuSpec,
    pub gnss: GnssSpec,
    pub rig: RigSpec,
    pub output: OutputSpec,
}

/// Default built-in duration (s).
pub const DEFAULT_DURATION_S: f64 = 600.0;

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            trajectory: None,
            segments: Vec::new(),
            reference_nav: None,
            seed: 1,
            traj_seed: 1,
            duration_s: None,
            gps_week: 2300,
            start_sow: 100_000.0,
            origin: [30.444_787_370_1, 114.471_863_204_7, 20.9],
            initial_heading_deg: 45.0,
            initial_speed_mps: 0.0,
            roll_gain_deg_per_mps2: 0.5,
            vibration: VibrationSpec::default(),
            imu: ImuSpec::preset("adis16465").unwrap_or_default(),
            gnss: GnssSpec::default(),
            rig: RigSpec::default(),
            output: OutputSpec::default(),
        }
    }
}

/// Keys that tag a variant of an internally tagged enum (temperature
/// `model`, segment and filter `kind`).
const TAG_KEYS: [&str; 2] = ["model", "kind"];

/// Merges `patch` into `base`: objects key by key, anything else replaced.
/// An object that names another variant (a different `model` or `kind`)
/// replaces the base object whole: the old variant's fields do not apply.
pub fn deep_merge(base: &mut Value, patch: Value) {
    let other_variant = |b: &Map<String, Value>, p: &Map<String, Value>| {
        TAG_KEYS.iter().any(|k| {
            p.get(*k)
                .is_some_and(|v| b.get(*k).is_some_and(|bv| bv != v))
        })
    };
    match (base, patch) {
        (Value::Object(b), Value::Object(p)) if !other_variant(b, &p) => {
            for (k, v) in p {
                match b.get_mut(&k) {
                    Some(slot) => deep_merge(slot, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (slot, v) => *slot = v,
    }
}

/// Sets `a.b.c = value` in a JSON object, creating tables on the way.
pub fn set_path(root: &mut Value, dotted: &str, value: Value) -> Result<(), Error> {
    let keys: Vec<&str> = dotted.split('.').collect();
    if keys.iter().any(|k| k.is_empty()) {
        return Err(Error::Invalid(format!(
            "'{dotted}' is not a key path like imu.gyro.arw_deg_sqrt_h"
        )));
    }
    let mut cur = root;
    for (i, k) in keys.iter().enumerate() {
        if !cur.is_object() {
            *cur = Value::Object(Map::new());
        }
        let obj = cur
            .as_object_mut()
            .ok_or_else(|| Error::Invalid("not a table".into()))?;
        if i + 1 == keys.len() {
            obj.insert((*k).to_string(), value);
            return Ok(());
        }
        cur = obj
            .entry((*k).to_string())
            .or_insert_with(|| Value::Object(Map::new()));
    }
    Ok(())
}

/// Parses the value of a `key=value` override as TOML (numbers, strings,
/// booleans, arrays, inline tables); a bare word is taken as a string.
pub fn parse_override(text: &str) -> Result<(String, Value), Error> {
    let (k, v) = text
        .split_once('=')
        .ok_or_else(|| Error::Invalid(format!("override '{text}' is not key=value")))?;
    let k = k.trim();
    let v = v.trim();
    let doc = format!("x = {v}");
    let value = match toml::from_str::<toml::Table>(&doc) {
        Ok(t) => t
            .get("x")
            .map(toml_to_json)
            .ok_or_else(|| Error::Invalid(format!("override '{text}' has no value")))?,
        Err(_) => Value::String(v.to_string()),
    };
    Ok((k.to_string(), value))
}

fn toml_to_json(v: &toml::Value) -> Value {
    match v {
        toml::Value::String(s) => Value::String(s.clone()),
        toml::Value::Integer(i) => Value::from(*i),
        toml::Value::Float(f) => {
            serde_json::Number::from_f64(*f).map_or(Value::Null, Value::Number)
        }
        toml::Value::Boolean(b) => Value::Bool(*b),
        toml::Value::Datetime(d) => Value::String(d.to_string()),
        toml::Value::Array(a) => Value::Array(a.iter().map(toml_to_json).collect()),
        toml::Value::Table(t) => Value::Object(
            t.iter()
                .map(|(k, v)| (k.clone(), toml_to_json(v)))
                .collect(),
        ),
    }
}

/// Named presets: a built-in trajectory with sensor and rig settings.
pub const PRESETS: &[&str] = &["demo", "hybrid"];

/// The layer of a named preset:
/// - `demo`: the `navsync demo` drive. The test track with an ADIS16465
///   (the default IMU) at 200 Hz and 1 Hz RTK; a logger whose 1 MHz
///   counter runs 20 ppm fast and drifts 7.5 ppm more as the board warms
///   up (0.5 ppm/°C, +15 °C with a 300 s time constant); one 40 s PPS
///   dropout, a few spurious and displaced pulses; GNSS messages 70–100 ms
///   late (receiver processing plus 38400 baud); GNSS time tags 10 ms late
///   (a receiver offset no clock synchronization can see, left for the
///   filter's time-offset state); two 30 s GNSS outages.
/// - `hybrid`: the commonest logger: 1PPS captured on the host counter
///   (40 ppm fast, +12.5 ppm as the board warms by 25 °C), the IMU on a
///   serial port without sync pin, its records stamped at receipt with a
///   latency uniform in 1–10 ms (FIFO), one frame in 10⁴ lost. Other
///   laws: `--set rig.software.imu_latency_law=exponential --set
///   rig.software.imu_latency_mean_s=0.002`.
pub fn preset_layer(name: &str) -> Option<Value> {
    match name {
        "demo" => Some(serde_json::json!({
            "trajectory": "test-track",
            "duration_s": 600.0,
            "imu": { "grade": "adis16465" },
            "gnss": {
                "outages": [[240.0, 30.0], [420.0, 30.0]],
                "time_offset_s": 0.010
            },
            "rig": {
                "sync": "hw",
                "counter": { "freq_error_ppm": 20.0, "temp_coeff_ppm_per_c": 0.5 },
                "temperature": { "model": "exponential", "t0_c": 20.0, "delta_c": 15.0, "tau_s": 300.0 },
                "pps": {
                    "dropouts": [[150.0, 40.0]],
                    "spurious_per_hour": 30.0,
                    "displaced_fraction": 0.005
                }
            }
        })),
        "hybrid" => Some(serde_json::json!({
            "trajectory": "test-track",
            "duration_s": 600.0,
            "imu": { "grade": "adis16465" },
            "rig": {
                "sync": "hybrid",
                "counter": { "freq_error_ppm": 40.0, "temp_coeff_ppm_per_c": 0.5 },
                "temperature": { "model": "exponential", "t0_c": 20.0, "delta_c": 25.0, "tau_s": 300.0 },
                "imu_link": { "loss_prob": 1e-4 },
                "software": { "imu_latency_s": [0.001, 0.010], "imu_latency_law": "uniform" }
            }
        })),
        _ => None,
    }
}

/// The base layer named by `--scenario`: a TOML file, a preset or a
/// built-in trajectory.
pub fn base_layer(name_or_path: &str) -> Result<Value, Error> {
    let path = Path::new(name_or_path);
    if name_or_path.ends_with(".toml") || path.is_file() {
        return Scenario::read_toml_layer(path);
    }
    Ok(preset_layer(name_or_path)
        .unwrap_or_else(|| serde_json::json!({ "trajectory": name_or_path })))
}

impl Scenario {
    /// Reads a user scenario file (TOML) as a sparse layer; unknown keys
    /// and bad values are reported with the file and line.
    pub fn read_toml_layer(path: &Path) -> Result<Value, Error> {
        let text = navsync::io::text::read_config_text(path)?;
        Self::toml_layer(&text, path)
    }

    /// [`Scenario::read_toml_layer`] on text.
    pub fn toml_layer(text: &str, path: &Path) -> Result<Value, Error> {
        // Full typed parse first, for located errors (unknown keys, types).
        toml::from_str::<Scenario>(text)
            .map_err(|e| Error::config(path, scenario_error(&e.to_string())))?;
        let table: toml::Table =
            toml::from_str(text).map_err(|e| Error::config(path, e.to_string()))?;
        Ok(toml_to_json(&toml::Value::Table(table)))
    }

    /// Builds the scenario from a sparse layer (file and overrides merged):
    /// defaults, then the IMU preset named by `imu.grade`, then the layer.
    pub fn from_layer(layer: Value) -> Result<Scenario, Error> {
        let grade = layer
            .get("imu")
            .and_then(|i| i.get("grade"))
            .and_then(Value::as_str)
            .unwrap_or("adis16465")
            .to_string();
        let preset = ImuSpec::preset(&grade).ok_or_else(|| {
            Error::Invalid(format!(
                "unknown IMU grade '{grade}' (presets: {})",
                IMU_PRESETS.join(", ")
            ))
        })?;
        let defaults = Scenario {
            imu: preset,
            ..Scenario::default()
        };
        let mut full =
            serde_json::to_value(&defaults).map_err(|e| Error::Invalid(e.to_string()))?;
        deep_merge(&mut full, layer);
        let scn: Scenario = serde_json::from_value(full)
            .map_err(|e| Error::Invalid(scenario_error(&e.to_string())))?;
        scn.validate()?;
        Ok(scn)
    }

    /// Checks what can be checked before running.
    pub fn validate(&self) -> Result<(), Error> {
        let bad = |m: String| Err(Error::Invalid(m));
        if let Some(name) = &self.trajectory
            && self.segments.is_empty()
            && !BUILTIN_SCENARIOS.contains(&name.as_str())
        {
            return bad(format!(
                "unknown scenario '{name}' (built-in: {}, {}; or give a TOML file with [[segments]])",
                BUILTIN_SCENARIOS.join(", "),
                PRESETS.join(", ")
            ));
        }
        if self.reference_nav.is_some() && (self.trajectory.is_some() || !self.segments.is_empty())
        {
            return bad(
                "give one of `reference_nav`, `trajectory` (a built-in) or `segments`".into(),
            );
        }
        if self.trajectory.is_some() && !self.segments.is_empty() {
            return bad("give either `trajectory` (a built-in) or `segments`, not both".into());
        }
        if let Some(d) = self.duration_s
            && !(d > 0.0 && d <= 7.0 * 86400.0)
        {
            return bad(format!("duration_s {d} must be within (0, 604800]"));
        }
        let [lat, lon, h] = self.origin;
        if !(lat.abs() < 89.0 && lon.abs() <= 360.0 && h.is_finite()) {
            return bad(format!(
                "origin {:?} must be [lat within ±89°, lon, height]",
                self.origin
            ));
        }
        if !(self.start_sow >= 0.0 && self.start_sow < 604_800.0) || self.gps_week < 0 {
            return bad("start_sow must be within a week and gps_week >= 0".into());
        }
        if !(self.initial_speed_mps >= 0.0 && self.roll_gain_deg_per_mps2.is_finite()) {
            return bad("initial_speed_mps must be >= 0 and roll_gain finite".into());
        }
        let n = self.imu.decimation_factor().map_err(Error::Invalid)?;
        self.imu.filter_delay_s().map_err(Error::Invalid)?;
        if n == 0 && self.imu.decimation == super::imu::Decimation::Point {
            return bad(
                "point decimation needs an internal sampling rate (imu.internal_rate_hz)".into(),
            );
        }
        self.gnss.validate().map_err(Error::Invalid)?;
        self.rig
            .validate(1.0 / self.imu.output_rate_hz)
            .map_err(Error::Invalid)?;
        if self.output.imu_err_interval_s.is_nan() || self.output.imu_err_interval_s <= 0.0 {
            return bad("output.imu_err_interval_s must be positive".into());
        }
        Ok(())
    }

    /// The trajectory's segments and the run's length.
    pub fn segments_and_duration(&self) -> Result<(Vec<Segment>, Option<f64>), Error> {
        if !self.segments.is_empty() {
            return Ok((self.segments.clone(), self.duration_s));
        }
        let name = self.trajectory.as_deref().unwrap_or("urban");
        let d = self.duration_s.unwrap_or(DEFAULT_DURATION_S);
        let mut segs = builtin_segments(name, d, self.traj_seed)
            .ok_or_else(|| Error::Invalid(format!("unknown scenario '{name}'")))?;
        // A built-in drive that starts in motion (initial_speed_mps > 0)
        // cruises through its opening standstill instead.
        if self.initial_speed_mps > 0.0
            && let Some(Segment::Static { duration_s }) = segs.first().cloned()
        {
            segs[0] = Segment::Cruise {
                duration_s: Some(duration_s),
                distance_m: None,
            };
        }
        Ok((segs, Some(d)))
    }
}

/// Makes serde's messages about the scenario friendlier.
fn scenario_error(msg: &str) -> String {
    format!("scenario: {msg}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imu::Decimation;

    #[test]
    fn layers_apply_in_order() {
        let text = r#"
seed = 42
duration_s = 120

[imu]
grade = "icm20602"
decimation = "point"

[imu.gyro]
arw_deg_sqrt_h = 0.5

[[segments]]
kind = "static"
duration_s = 10

[[segments]]
kind = "accelerate"
speed_mps = 10
"#;
        let mut layer = Scenario::toml_layer(text, Path::new("s.toml")).unwrap();
        let (k, v) = parse_override("gnss.rate_hz=10").unwrap();
        set_path(&mut layer, &k, v).unwrap();
        let scn = Scenario::from_layer(layer).unwrap();
        assert_eq!(scn.seed, 42);
        assert_eq!(scn.imu.grade, "icm20602");
        assert_eq!(scn.imu.decimation, Decimation::Point);
        assert_eq!(scn.imu.gyro.arw_deg_sqrt_h, 0.5);
        // Untouched preset values stay (ICM-20602: 1 kHz, ±250°/s).
        assert_eq!(scn.imu.internal_rate_hz, 1000.0);
        assert_eq!(scn.imu.gyro.range_deg_s, 250.0);
        assert_eq!(scn.gnss.rate_hz, 10.0);
        assert_eq!(scn.segments.len(), 2);
        let (segs, d) = scn.segments_and_duration().unwrap();
        assert_eq!((segs.len(), d), (2, Some(120.0)));
    }

    #[test]
    fn unknown_keys_and_bad_values_are_located() {
        let err = Scenario::toml_layer("seed = 1\n[imu.gyro]\narw = 0.1\n", Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("s.toml") && err.contains("arw") && err.contains("line 3"),
            "{err}"
        );
        let err = Scenario::toml_layer("[[segments]]\nkind = \"fly\"\n", Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("fly"), "{err}");
        let err = Scenario::from_layer(serde_json::json!({"imu": {"grade": "mems9000"}}))
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown IMU grade 'mems9000'"), "{err}");
        let err = Scenario::from_layer(serde_json::json!({"trajectory": "moon"}))
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown scenario 'moon'"), "{err}");
        let err = Scenario::from_layer(serde_json::json!({"gnss": {"rate_hz": 0}}))
            .unwrap_err()
            .to_string();
        assert!(err.contains("GNSS rate"), "{err}");
        let err = Scenario::from_layer(serde_json::json!({"imu": {"internal_rate_hz": 1500}}))
            .unwrap_err()
            .to_string();
        assert!(err.contains("integer multiple"), "{err}");
        assert!(parse_override("nokey").is_err());
        let (k, v) = parse_override("rig.sync=sw").unwrap();
        assert_eq!((k.as_str(), v), ("rig.sync", Value::String("sw".into())));
    }

    #[test]
    fn another_variant_replaces_the_default_one() {
        let mut layer = serde_json::json!({});
        let (k, v) =
            parse_override("rig.temperature={model=\"ramp\",t0_c=20,rate_c_per_min=1}").unwrap();
        set_path(&mut layer, &k, v).unwrap();
        let scn = Scenario::from_layer(layer).unwrap();
        assert!(matches!(
            scn.rig.temperature,
            crate::clock::TemperatureSpec::Ramp { rate_c_per_min, .. } if rate_c_per_min == 1.0
        ));
        // The same variant still merges field by field.
        let mut base = serde_json::json!({"model": "constant", "celsius": 25.0, "x": 1});
        deep_merge(&mut base, serde_json::json!({"celsius": 30.0}));
        assert_eq!(
            base,
            serde_json::json!({"model": "constant", "celsius": 30.0, "x": 1})
        );
    }

    #[test]
    fn the_demo_preset_builds() {
        let scn = Scenario::from_layer(base_layer("demo").unwrap()).unwrap();
        assert_eq!(scn.trajectory.as_deref(), Some("test-track"));
        assert_eq!(scn.rig.pps.dropouts.len(), 1);
        assert_eq!(scn.gnss.outages.len(), 2);
        assert!(matches!(
            scn.rig.temperature,
            crate::clock::TemperatureSpec::Exponential { .. }
        ));
        let err = Scenario::from_layer(base_layer("moon").unwrap()).unwrap_err();
        assert!(err.to_string().contains("demo"), "{err}");
    }

    #[test]
    fn builtins_default_to_ten_minutes() {
        let scn = Scenario::from_layer(serde_json::json!({"trajectory": "test-track"})).unwrap();
        let (segs, d) = scn.segments_and_duration().unwrap();
        assert!(!segs.is_empty());
        assert_eq!(d, Some(600.0));
    }
}
