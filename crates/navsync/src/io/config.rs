//! The KF-GINS YAML configuration, read unchanged (FORMATS.md §1), and
//! converted to SI units as KF-GINS does (`kf_gins.cpp`, `loadConfig`):
//! ARW deg/√h, VRW m/s/√h, gyro bias deg/h, accelerometer bias mGal, scale
//! factors ppm, correlation time hours.
//!
//! A missing key is an error naming it and what it should hold; an unknown
//! key is reported (with the closest known key when it looks misspelled).

#![warn(missing_docs)]

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde_json::Value;

use crate::attitude::Euler;
use crate::earth::Geodetic;
use crate::error::{Diagnostics, Error};
use crate::types::{ImuErrors, ImuNoise, InitialStd};

const DEG: f64 = std::f64::consts::PI / 180.0;

/// Every key KF-GINS reads, with what it holds (for messages).
const KEYS: &[(&str, &str)] = &[
    ("imupath", "the IMU file path"),
    ("gnsspath", "the GNSS file path"),
    ("outputpath", "the output folder"),
    (
        "imudatalen",
        "the number of IMU file columns (7, or 8 with odometer speed)",
    ),
    ("imudatarate", "the IMU data rate in Hz"),
    ("starttime", "the start time in GPS seconds of week"),
    (
        "endtime",
        "the end time in GPS seconds of week, or -1 for the end of the file",
    ),
    (
        "initpos",
        "[latitude deg, longitude deg, ellipsoidal height m]",
    ),
    ("initvel", "[v_north, v_east, v_down] in m/s"),
    ("initatt", "[roll, pitch, yaw] in deg"),
    ("initgyrbias", "initial gyro biases [x, y, z] in deg/h"),
    (
        "initaccbias",
        "initial accelerometer biases [x, y, z] in mGal",
    ),
    (
        "initgyrscale",
        "initial gyro scale factors [x, y, z] in ppm",
    ),
    (
        "initaccscale",
        "initial accelerometer scale factors [x, y, z] in ppm",
    ),
    (
        "initposstd",
        "initial position std [north, east, down] in m",
    ),
    (
        "initvelstd",
        "initial velocity std [north, east, down] in m/s",
    ),
    (
        "initattstd",
        "initial attitude std [roll, pitch, yaw] in deg",
    ),
    ("initbgstd", "initial gyro bias std [x, y, z] in deg/h"),
    (
        "initbastd",
        "initial accelerometer bias std [x, y, z] in mGal",
    ),
    ("initsgstd", "initial gyro scale std [x, y, z] in ppm"),
    (
        "initsastd",
        "initial accelerometer scale std [x, y, z] in ppm",
    ),
    (
        "imunoise",
        "the IMU noise block (arw, vrw, gbstd, abstd, gsstd, asstd, corrtime)",
    ),
    (
        "antlever",
        "the GNSS antenna lever arm [forward, right, down] in m",
    ),
];

const NOISE_KEYS: &[(&str, &str)] = &[
    ("arw", "angle random walk [x, y, z] in deg/sqrt(h)"),
    ("vrw", "velocity random walk [x, y, z] in m/s/sqrt(h)"),
    ("gbstd", "gyro bias instability [x, y, z] in deg/h"),
    ("abstd", "accelerometer bias instability [x, y, z] in mGal"),
    ("gsstd", "gyro scale-factor instability [x, y, z] in ppm"),
    (
        "asstd",
        "accelerometer scale-factor instability [x, y, z] in ppm",
    ),
    ("corrtime", "the Gauss-Markov correlation time in hours"),
];

/// A KF-GINS configuration in SI units.
#[derive(Clone, Debug)]
pub struct KfGinsConfig {
    /// The configuration file itself.
    pub path: PathBuf,
    /// IMU file (`imupath`); relative paths as KF-GINS resolves them, else next
    /// to the configuration.
    pub imu_path: PathBuf,
    /// GNSS file (`gnsspath`), resolved like `imu_path`.
    pub gnss_path: PathBuf,
    /// Output folder (`outputpath`), as written.
    pub output_path: PathBuf,
    /// IMU data rate (Hz, `imudatarate`).
    pub imu_rate_hz: f64,
    /// Start, seconds of week.
    pub start_sow: f64,
    /// End, seconds of week; `None` for the end of the data.
    pub end_sow: Option<f64>,
    /// Initial position (`initpos`); zero when absent (alignment finds it).
    pub init_pos: Geodetic,
    /// Initial velocity N, E, D (m/s, `initvel`); zero when absent.
    pub init_vel: Vector3<f64>,
    /// Initial attitude (`initatt`, read in deg); zero when absent.
    pub init_att: Euler,
    /// Whether `initatt` was given (then `initpos` and `initvel` are
    /// required too); without it the run starts from an alignment
    /// ([`crate::align`]), and an `initpos`/`initvel` given is still read.
    pub init_state_given: bool,
    pub(crate) init_imu: ImuErrors,
    /// Initial σ of the error state (`initposstd` … `initsastd`), SI.
    pub init_std: InitialStd,
    /// IMU noise model (`imunoise` block), SI.
    pub noise: ImuNoise,
    pub(crate) antenna_lever: Vector3<f64>,
}

impl KfGinsConfig {
    /// The antenna lever arm (`antlever`), IMU to antenna, FRD (m).
    pub fn antenna_lever_m(&self) -> [f64; 3] {
        self.antenna_lever.into()
    }

    /// Reads and checks a KF-GINS YAML file. Problems that do not stop the
    /// run (unknown keys, a path found next to the config rather than in
    /// the working directory) go into `diag`.
    pub fn load(path: &Path, diag: &mut Diagnostics) -> Result<Self, Error> {
        let text = crate::io::text::read_config_text(path)?;
        Self::parse(&text, path, diag)
    }

    /// Parses YAML text; `path` names it in messages and anchors the
    /// fallback for relative data paths.
    pub fn parse(text: &str, path: &Path, diag: &mut Diagnostics) -> Result<Self, Error> {
        let root: Value = serde_saphyr::from_str(text)
            .map_err(|e| Error::config(path, format!("not valid YAML: {e}")))?;
        let Value::Object(map) = &root else {
            return Err(Error::config(
                path,
                "expected a mapping of KF-GINS keys at the top level",
            ));
        };
        let known: Vec<&str> = KEYS.iter().map(|k| k.0).collect();
        let unknown: Vec<&String> = map
            .keys()
            .filter(|k| !known.contains(&k.as_str()))
            .collect();
        for k in &unknown {
            let hint = closest(k, &known)
                .map(|c| format!(" (did you mean '{c}'?)"))
                .unwrap_or_default();
            diag.push(path, 0, format!("unknown key '{k}' ignored{hint}"));
        }
        let cx = Ctx {
            path,
            map,
            unknown: &unknown,
            block: "",
        };

        let noise_v = cx.get("imunoise")?;
        let Value::Object(noise_map) = noise_v else {
            return Err(Error::config(
                path,
                "key 'imunoise' must be a mapping of arw, vrw, gbstd, abstd, gsstd, asstd, corrtime",
            ));
        };
        let noise_known: Vec<&str> = NOISE_KEYS.iter().map(|k| k.0).collect();
        let noise_unknown: Vec<&String> = noise_map
            .keys()
            .filter(|k| !noise_known.contains(&k.as_str()))
            .collect();
        for k in &noise_unknown {
            let hint = closest(k, &noise_known)
                .map(|c| format!(" (did you mean '{c}'?)"))
                .unwrap_or_default();
            diag.push(path, 0, format!("unknown key 'imunoise.{k}' ignored{hint}"));
        }
        let nx = Ctx {
            path,
            map: noise_map,
            unknown: &noise_unknown,
            block: "imunoise.",
        };

        // Each figure in the range a sensor sheet allows for it (the same
        // datasheet units: deg/√h, m/s/√h, deg/h, mGal, ppm; corrtime in h).
        let ranged = |key: &str, sheet_key: &str| -> Result<Vector3<f64>, Error> {
            let v = nx.vec3(key)?;
            let (lo, hi) = crate::sensor::figure_range(sheet_key);
            match v.iter().find(|x| !(lo..=hi).contains(*x)) {
                Some(x) => Err(Error::config(
                    path,
                    format!("key 'imunoise.{key}' must hold numbers within [{lo}, {hi}], got {x}"),
                )),
                None => Ok(v),
            }
        };
        let arw = ranged("arw", "arw_deg_sqrt_h")? * (DEG / 60.0);
        let vrw = ranged("vrw", "vrw_mps_sqrt_h")? / 60.0;
        let gbstd = ranged("gbstd", "gyro_bias_instability_deg_h")? * (DEG / 3600.0);
        let abstd = ranged("abstd", "accel_bias_instability_mgal")? * 1e-5;
        let gsstd = ranged("gsstd", "gyro_scale_ppm")? * 1e-6;
        let asstd = ranged("asstd", "accel_scale_ppm")? * 1e-6;
        let corr_h = nx.number("corrtime")?;
        let (lo_s, hi_s) = crate::sensor::figure_range("bias_corr_time_s");
        if !(lo_s..=hi_s).contains(&(corr_h * 3600.0)) {
            return Err(Error::config(
                path,
                format!(
                    "key 'imunoise.corrtime' must be within [{}, {}] hours, got {corr_h}",
                    lo_s / 3600.0,
                    hi_s / 3600.0
                ),
            ));
        }
        let noise = ImuNoise {
            arw,
            vrw,
            gyro_bias_sd: gbstd,
            accel_bias_sd: abstd,
            gyro_scale_sd: gsstd,
            accel_scale_sd: asstd,
            corr_time_s: corr_h * 3600.0,
        };

        // The initial state is optional as a whole: without `initatt` the
        // run aligns itself (levelling and GNSS course), and then
        // `initpos`/`initvel` may be left out too.
        let init_state_given = map.contains_key("initatt");
        let opt3 = |key: &str| -> Result<Vector3<f64>, Error> {
            if init_state_given || map.contains_key(key) {
                cx.vec3(key)
            } else {
                Ok(Vector3::zeros())
            }
        };
        let pos = opt3("initpos")?;
        if pos.x.abs() > 90.0 {
            return Err(Error::config(
                path,
                format!("key 'initpos': latitude {} deg is out of range", pos.x),
            ));
        }
        let att = opt3("initatt")?;
        let figure_max = |key: &str| crate::sensor::figure_range(key).1;
        // An initial σ above `max` (in the key's own unit) is a unit slip
        // or a typo (1e308) that would overflow the covariance; the
        // bounds match the sheet's figure ranges (`sensor::figure_range`)
        // or are the physical limit (180°, the earth's size).
        let opt_std = |key: &str, default: Vector3<f64>, max: f64| -> Result<Vector3<f64>, Error> {
            let v = match map.get(key) {
                Some(_) => cx.vec3(key)?,
                None => return Ok(default),
            };
            if v.iter()
                .any(|x| !(x.is_finite() && (0.0..=max).contains(x)))
            {
                return Err(Error::config(
                    path,
                    format!(
                        "key '{key}' must be within 0…{max:e} per axis, got [{}, {}, {}]",
                        v.x, v.y, v.z
                    ),
                ));
            }
            Ok(v)
        };
        let imu_rate_hz = cx.number("imudatarate")?;
        if imu_rate_hz <= 0.0 {
            return Err(Error::config(
                path,
                format!("key 'imudatarate' must be positive, got {imu_rate_hz}"),
            ));
        }
        let imu_columns = cx.number("imudatalen")?;
        if imu_columns != 7.0 && imu_columns != 8.0 {
            return Err(Error::config(
                path,
                format!("key 'imudatalen' must be 7 or 8, got {imu_columns}"),
            ));
        }
        let end = cx.number("endtime")?;
        let start_sow = cx.number("starttime")?;
        let end_sow = if end < 0.0 { None } else { Some(end) };
        if let Some(e) = end_sow
            && e < start_sow
        {
            return Err(Error::config(
                path,
                format!("endtime {e} is before starttime {start_sow}"),
            ));
        }

        Ok(KfGinsConfig {
            path: path.to_path_buf(),
            imu_path: resolve_input(&cx.string("imupath")?, path, diag),
            gnss_path: resolve_input(&cx.string("gnsspath")?, path, diag),
            output_path: PathBuf::from(cx.string("outputpath")?),
            imu_rate_hz,
            start_sow,
            end_sow,
            init_pos: Geodetic::from_deg(pos.x, pos.y, pos.z),
            init_vel: opt3("initvel")?,
            init_att: Euler::from_deg(att.x, att.y, att.z),
            init_state_given,
            init_imu: ImuErrors {
                gyro_bias: cx.vec3("initgyrbias")? * (DEG / 3600.0),
                accel_bias: cx.vec3("initaccbias")? * 1e-5,
                gyro_scale: cx.vec3("initgyrscale")? * 1e-6,
                accel_scale: cx.vec3("initaccscale")? * 1e-6,
                ..ImuErrors::default()
            },
            init_std: InitialStd {
                pos: opt_std("initposstd", Vector3::repeat(1.0), 1e7)?,
                vel: opt_std("initvelstd", Vector3::repeat(0.1), 1e3)?,
                att: opt_std("initattstd", Vector3::repeat(1.0), 180.0)? * DEG,
                gyro_bias: opt_std(
                    "initbgstd",
                    gbstd / (DEG / 3600.0),
                    figure_max("gyro_turn_on_bias_deg_h"),
                )? * (DEG / 3600.0),
                accel_bias: opt_std(
                    "initbastd",
                    abstd / 1e-5,
                    figure_max("accel_turn_on_bias_mgal"),
                )? * 1e-5,
                gyro_scale: opt_std("initsgstd", gsstd / 1e-6, figure_max("gyro_scale_ppm"))?
                    * 1e-6,
                accel_scale: opt_std("initsastd", asstd / 1e-6, figure_max("accel_scale_ppm"))?
                    * 1e-6,
            },
            noise,
            antenna_lever: cx.vec3("antlever")?,
        })
    }
}

/// KF-GINS resolves relative paths against the working directory. When the
/// file is not there but is next to the configuration, use that and say so.
fn resolve_input(raw: &str, config: &Path, diag: &mut Diagnostics) -> PathBuf {
    let p = PathBuf::from(raw);
    if p.is_absolute() || p.exists() {
        return p;
    }
    if let Some(dir) = config.parent() {
        let alt = dir.join(&p);
        if alt.exists() {
            diag.push(
                config,
                0,
                format!(
                    "'{raw}' is not in the working directory; using {} next to the configuration",
                    alt.display()
                ),
            );
            return alt;
        }
    }
    p
}

struct Ctx<'a> {
    path: &'a Path,
    map: &'a serde_json::Map<String, Value>,
    unknown: &'a [&'a String],
    block: &'a str,
}

impl Ctx<'_> {
    fn describe(&self, key: &str) -> &'static str {
        KEYS.iter()
            .chain(NOISE_KEYS)
            .find(|k| k.0 == key)
            .map(|k| k.1)
            .unwrap_or("a value")
    }

    fn get(&self, key: &str) -> Result<&Value, Error> {
        self.map.get(key).ok_or_else(|| {
            let candidates: Vec<&str> = self.unknown.iter().map(|s| s.as_str()).collect();
            let hint = closest(key, &candidates)
                .map(|c| format!(" (found '{}{c}', misspelled?)", self.block))
                .unwrap_or_default();
            Error::config(
                self.path,
                format!(
                    "missing key '{}{key}': expected {}{hint}",
                    self.block,
                    self.describe(key)
                ),
            )
        })
    }

    fn number(&self, key: &str) -> Result<f64, Error> {
        let v = self.get(key)?;
        as_number(v).ok_or_else(|| {
            Error::config(
                self.path,
                format!(
                    "key '{}{key}' must be a number ({}), got {v}",
                    self.block,
                    self.describe(key)
                ),
            )
        })
    }

    fn string(&self, key: &str) -> Result<String, Error> {
        match self.get(key)? {
            Value::String(s) if !s.trim().is_empty() => Ok(s.clone()),
            v => Err(Error::config(
                self.path,
                format!(
                    "key '{}{key}' must be a path ({}), got {v}",
                    self.block,
                    self.describe(key)
                ),
            )),
        }
    }

    fn vec3(&self, key: &str) -> Result<Vector3<f64>, Error> {
        let v = self.get(key)?;
        let bad = || {
            Error::config(
                self.path,
                format!(
                    "key '{}{key}' must be a list of 3 numbers ({}), got {v}",
                    self.block,
                    self.describe(key)
                ),
            )
        };
        let Value::Array(items) = v else {
            return Err(bad());
        };
        if items.len() != 3 {
            return Err(bad());
        }
        let mut out = Vector3::zeros();
        for (i, it) in items.iter().enumerate() {
            out[i] = as_number(it).ok_or_else(bad)?;
        }
        Ok(out)
    }
}

fn as_number(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64().filter(|x| x.is_finite()),
        Value::String(s) => s.trim().parse::<f64>().ok().filter(|x| x.is_finite()),
        _ => None,
    }
}

/// The candidate closest to `word` by edit distance, if close enough to be
/// a likely misspelling.
fn closest<'a>(word: &str, candidates: &[&'a str]) -> Option<&'a str> {
    candidates
        .iter()
        .map(|c| (edit_distance(word, c), *c))
        .filter(|(d, c)| *d <= 2.max(c.len() / 4))
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for i in 1..=a.len() {
        let mut cur = vec![i; b.len() + 1];
        for j in 1..=b.len() {
            let sub = prev[j - 1] + usize::from(a[i - 1] != b[j - 1]);
            cur[j] = sub.min(prev[j] + 1).min(cur[j - 1] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = r#"
imupath: "./imu.txt"
gnsspath: "./gnss.txt"
outputpath: "./out"
imudatalen: 7
imudatarate: 200
starttime: 100000.005000000
endtime: -1
initpos: [ 30.444787370100, 114.471863204700, 20.900000000000 ]
initvel: [ 0.0, 0.0, -0.0 ]
initatt: [ 0.0, 0.0, 45.0 ]
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
antlever: [ 0.1, 0.5, -1.2 ]
"#;

    #[test]
    fn parses_and_converts_units() {
        let mut d = Diagnostics::default();
        let c = KfGinsConfig::parse(SAMPLE, Path::new("cfg.yaml"), &mut d).unwrap();
        assert!(d.is_empty(), "{d:?}");
        assert_eq!(c.imu_rate_hz, 200.0);
        assert_eq!(c.start_sow, 100000.005);
        assert!(c.end_sow.is_none());
        assert!((c.noise.arw.x - 0.15 * DEG / 60.0).abs() < 1e-15);
        assert!((c.noise.corr_time_s - 3600.0).abs() < 1e-9);
        // optional initial bias std defaults to the noise block's values
        assert!((c.init_std.gyro_bias.x - 2.0 * DEG / 3600.0).abs() < 1e-15);
        assert!((c.init_std.accel_bias.y - 3.6e-5).abs() < 1e-15);
        assert!((c.init_att.yaw_rad - 45.0 * DEG).abs() < 1e-15);
        assert_eq!(c.antenna_lever, Vector3::new(0.1, 0.5, -1.2));
    }

    #[test]
    fn missing_and_misspelled_keys_are_named() {
        let mut d = Diagnostics::default();
        let text = SAMPLE.replace("initpos:", "intpos:");
        let err = KfGinsConfig::parse(&text, Path::new("cfg.yaml"), &mut d)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cfg.yaml")
                && err.contains("missing key 'initpos'")
                && err.contains("'intpos'"),
            "{err}"
        );
        assert!(
            d.items[0].message.contains("did you mean 'initpos'"),
            "{:?}",
            d.items
        );

        let text = SAMPLE.replace("  corrtime: 1.0\n", "");
        let err = KfGinsConfig::parse(&text, Path::new("cfg.yaml"), &mut d)
            .unwrap_err()
            .to_string();
        assert!(err.contains("missing key 'imunoise.corrtime'"), "{err}");

        // An absurd noise figure names its key (1e308 passed before; YAML
        // refuses .inf and .nan here, naming the line).
        for (from, to, key) in [
            ("arw: [ 0.15,", "arw: [ 1e308,", "'imunoise.arw'"),
            ("vrw: [ 0.04,", "vrw: [ -0.04,", "'imunoise.vrw'"),
            ("vrw: [ 0.04,", "vrw: [ 1e300,", "'imunoise.vrw'"),
            ("gbstd: [ 2.0,", "gbstd: [ 1e300,", "'imunoise.gbstd'"),
            ("abstd: [ 3.6,", "abstd: [ 1e300,", "'imunoise.abstd'"),
            ("gsstd: [ 500.0,", "gsstd: [ 5e300,", "'imunoise.gsstd'"),
            ("asstd: [ 500.0,", "asstd: [ 5e300,", "'imunoise.asstd'"),
            ("corrtime: 1.0", "corrtime: 1e308", "'imunoise.corrtime'"),
            ("corrtime: 1.0", "corrtime: 0", "'imunoise.corrtime'"),
            // and an initial σ (1e308 passed before).
            (
                "initposstd: [ 0.05,",
                "initposstd: [ 1e308,",
                "'initposstd'",
            ),
            (
                "initvelstd: [ 0.05,",
                "initvelstd: [ -0.05,",
                "'initvelstd'",
            ),
            ("initattstd: [ 0.1,", "initattstd: [ 181,", "'initattstd'"),
            (
                "initaccscale: [ 0, 0, 0 ]",
                "initaccscale: [ 0, 0, 0 ]\ninitbgstd: [ 1e308, 1, 1 ]",
                "'initbgstd'",
            ),
            (
                "initaccscale: [ 0, 0, 0 ]",
                "initaccscale: [ 0, 0, 0 ]\ninitsastd: [ 1, 1, 1e9 ]",
                "'initsastd'",
            ),
        ] {
            let text = SAMPLE.replace(from, to);
            assert_ne!(text, SAMPLE);
            let err = KfGinsConfig::parse(&text, Path::new("cfg.yaml"), &mut d)
                .unwrap_err()
                .to_string();
            assert!(err.contains("cfg.yaml") && err.contains(key), "{to}: {err}");
        }

        let text = SAMPLE.replace("antlever: [ 0.1, 0.5, -1.2 ]", "antlever: [ 0.1, 0.5 ]");
        let err = KfGinsConfig::parse(&text, Path::new("cfg.yaml"), &mut d)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("'antlever' must be a list of 3 numbers"),
            "{err}"
        );

        let err = KfGinsConfig::parse("just text", Path::new("cfg.yaml"), &mut d)
            .unwrap_err()
            .to_string();
        assert!(err.contains("cfg.yaml"), "{err}");

        let err = KfGinsConfig::load(Path::new("/no/such/config.yaml"), &mut d)
            .unwrap_err()
            .to_string();
        assert!(err.contains("/no/such/config.yaml"), "{err}");
    }
}
