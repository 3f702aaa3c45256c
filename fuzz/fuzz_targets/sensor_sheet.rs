//! Fuzzes the sensor sheet (`navsync::sensor::SensorSheet::parse`) on raw
//! YAML, or on a real sheet (`navsync init`'s template) with fuzzed bytes
//! spliced into its values. Beyond "no panic": a sheet accepted gives
//! positive noise figures and initial σ whose squares (the filter's
//! covariance) are finite, and finite lever arms.
#![no_main]

use std::path::Path;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use navsync::sensor::{SensorSheet, template};

const ALPHABET: &[u8] = b"0123456789.-+e \n:[],#abcdefinorstuy_";

fn base() -> &'static str {
    static T: OnceLock<String> = OnceLock::new();
    T.get_or_init(|| template("adis16465").unwrap_or_default())
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 3 {
        return;
    }
    let text = if data[0] & 1 == 0 {
        String::from_utf8_lossy(&data[1..]).into_owned()
    } else {
        // Replace a stretch of the template (from a fuzzed offset) by
        // fuzzed characters.
        let t = base().as_bytes();
        let at = (usize::from(data[1]) << 8 | usize::from(data[2])) % t.len().max(1);
        let mut s = t[..at].to_vec();
        s.extend(
            data[3..]
                .iter()
                .map(|b| ALPHABET[*b as usize % ALPHABET.len()]),
        );
        let skip = (at + data.len() % 16).min(t.len());
        s.extend_from_slice(&t[skip..]);
        String::from_utf8_lossy(&s).into_owned()
    };
    let path = Path::new("sensor.yaml");
    let Ok(sheet) = SensorSheet::parse(&text, path) else {
        return;
    };
    let f = sheet
        .imu_figures(path)
        .expect("a parsed sheet has its IMU figures");
    let n = f.noise();
    let s = f.initial_std();
    for v in [
        n.arw,
        n.vrw,
        n.gyro_bias_sd,
        n.accel_bias_sd,
        n.gyro_scale_sd,
        n.accel_scale_sd,
    ] {
        // Squared: the filter's covariance must not overflow (1e308 did).
        assert!(v.iter().all(|x| (x * x).is_finite() && *x > 0.0), "{n:?}");
    }
    assert!(n.corr_time_s.is_finite() && n.corr_time_s > 0.0, "{n:?}");
    assert!(
        (n.gyro_bias_sd.x.powi(2) / n.corr_time_s).is_finite(),
        "{n:?}"
    );
    for v in [
        s.pos,
        s.vel,
        s.att,
        s.gyro_bias,
        s.accel_bias,
        s.gyro_scale,
        s.accel_scale,
    ] {
        assert!(v.iter().all(|x| (x * x).is_finite() && *x > 0.0), "{s:?}");
    }
    assert!(
        sheet
            .antenna_lever_m
            .iter()
            .chain(&sheet.mount_deg)
            .all(|x| x.is_finite())
    );
    if let Some(r) = sheet.imu.rate_hz {
        assert!(r.is_finite() && r > 0.0 && (1.0 / r) > 0.0);
    }
});
