//! A simulated odometer speed file made from a truth trajectory
//! (`navsync speed-sim`).

use std::path::Path;

use nalgebra::Vector3;
use serde::Serialize;

use navsync::error::{Diagnostics, Error};
use navsync::time::GpsTime;

/// Settings of a simulated odometer made from a truth trajectory.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct SpeedSimOptions {
    pub rate_hz: f64,
    /// Scale error s: reported = (1 + s)·true + noise.
    pub scale_error: f64,
    pub noise_sd_mps: f64,
    /// Output resolution (m/s); 0 keeps full precision.
    pub resolution_mps: f64,
    pub seed: u64,
}

impl Default for SpeedSimOptions {
    fn default() -> Self {
        SpeedSimOptions {
            rate_hz: 20.0,
            scale_error: 0.01,
            noise_sd_mps: 0.05,
            resolution_mps: 0.01,
            seed: 1,
        }
    }
}

/// Writes a simulated speed file from a truth trajectory (11-column nav
/// format): the forward body-frame speed (C_n^b v^n)_x of the trajectory
/// (the IMU centre), interpolated at the output rate, times (1 + scale
/// error), plus white noise, rounded to the resolution. Returns the number
/// of lines written.
pub fn simulate_speed_file(
    truth: &Path,
    out: &Path,
    o: &SpeedSimOptions,
    diag: &mut Diagnostics,
) -> Result<usize, Error> {
    use rand::RngExt;
    use rand::SeedableRng;
    use rand_distr::StandardNormal;
    use std::io::Write;

    let recs = navsync::io::kfgins::NavReader::read_all(truth, diag)?;
    let file = std::fs::File::create(out).map_err(|e| Error::io(out, e))?;
    let mut w = std::io::BufWriter::new(file);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(o.seed);
    let forward = |r: &navsync::io::kfgins::NavRecord| {
        let att = navsync::attitude::Euler::from_deg(r.att_deg[0], r.att_deg[1], r.att_deg[2]);
        (navsync::attitude::euler_to_dcm(&att).transpose() * Vector3::from(r.vel)).x
    };
    writeln!(
        w,
        "# simulated odometer from {}: rate {} Hz, scale error {}, noise {} m/s, resolution {} m/s, seed {}\n# sow speed_mps",
        truth.display(),
        o.rate_hz,
        o.scale_error,
        o.noise_sd_mps,
        o.resolution_mps,
        o.seed
    )
    .map_err(|e| Error::io(out, e))?;
    let step_ns = (1e9 / o.rate_hz).round() as i64;
    let Some(first) = recs.first() else {
        return Err(Error::NoData {
            path: truth.to_path_buf(),
            msg: "no records".into(),
        });
    };
    // Start on a whole multiple of the output period.
    let mut t = GpsTime::from_ns((first.time.ns() + step_ns - 1) / step_ns * step_ns);
    let mut i = 0;
    let mut n = 0;
    while i + 1 < recs.len() {
        while i + 1 < recs.len() && recs[i + 1].time < t {
            i += 1;
        }
        if i + 1 >= recs.len() {
            break;
        }
        let (a, b) = (&recs[i], &recs[i + 1]);
        let f = (t - a.time) as f64 / (b.time - a.time) as f64;
        let v = forward(a) + f * (forward(b) - forward(a));
        let noise: f64 = rng.sample(StandardNormal);
        let mut m = (1.0 + o.scale_error) * v + o.noise_sd_mps * noise;
        if o.resolution_mps > 0.0 {
            m = (m / o.resolution_mps).round() * o.resolution_mps;
        }
        let mut line = Vec::with_capacity(40);
        t.write_sow(&mut line);
        write!(line, " {m:.4}").ok();
        line.push(b'\n');
        w.write_all(&line).map_err(|e| Error::io(out, e))?;
        n += 1;
        t = t + step_ns;
    }
    w.flush().map_err(|e| Error::io(out, e))?;
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync::reduced::SpeedStream;

    #[test]
    fn simulated_speed_follows_the_truth_with_its_scale_error() {
        let dir = navsync::testfiles::TestDir::new("speedsim");
        let truth = dir.join("truth.nav");
        // Heading 90° (east) at 12 m/s, body forward = east.
        let mut s = String::new();
        for k in 0..=200 {
            s.push_str(&format!(
                "2300 {:.3} 30.0 114.0 10.0 0.0 12.0 0.0 0.0 0.0 90.0\n",
                1000.0 + k as f64 * 0.01
            ));
        }
        std::fs::write(&truth, s).unwrap();
        let out = dir.join("speed.txt");
        let o = SpeedSimOptions {
            rate_hz: 10.0,
            scale_error: 0.02,
            noise_sd_mps: 0.0,
            resolution_mps: 0.0,
            seed: 1,
        };
        let mut d = Diagnostics::default();
        let n = simulate_speed_file(&truth, &out, &o, &mut d).unwrap();
        assert_eq!(n, 21, "1000.0 to 1002.0 s inclusive at 10 Hz");
        let mut st = SpeedStream::open(&out, 2300, 0.5).unwrap();
        let v = st
            .at(GpsTime::from_week_sow(2300, 1001.0), &mut d)
            .unwrap()
            .unwrap();
        assert!((v - 12.24).abs() < 1e-9, "{v}");
    }
}
