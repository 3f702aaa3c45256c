//! Fuzzes the KF-GINS text readers (`navsync::io::kfgins`: IMU increments,
//! GNSS fixes of 7 or 13 columns in both layouts, navigation/truth files)
//! on raw text, or on lines built from the characters such files hold and
//! whole numeric tokens. Beyond "no panic": every record returned is finite
//! and plausible (`navsync::io::plausible`) and times increase.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync::Diagnostics;
use navsync::io::kfgins::{GnssLayout, GnssReader, ImuReader, NavReader};
use navsync::io::plausible::{increment_problem, position_problem, velocity_problem};

const ALPHABET: &[u8] = b"0123456789.-+ e\n\t,#";
const SEEDS: [&str; 10] = [
    "100000.005",
    "100000.010",
    "-0.049",
    "1.2e-5",
    "30.444787370100",
    "114.471863204700",
    "20.9",
    "0.02",
    "1e308",
    "2300",
];

fuzz_target!(|data: &[u8]| {
    if data.is_empty() {
        return;
    }
    let (mode, rest) = (data[0], &data[1..]);
    let mut text = Vec::new();
    if mode & 1 == 0 {
        text.extend_from_slice(rest);
    } else {
        for &b in rest {
            if b & 0x80 != 0 {
                text.extend_from_slice(SEEDS[b as usize % SEEDS.len()].as_bytes());
                text.push(b' ');
            } else {
                text.push(ALPHABET[b as usize % ALPHABET.len()]);
            }
        }
    }
    let week = i64::from(mode >> 6) * 1200;
    let mut d = Diagnostics::with_cap(16);
    match (mode >> 1) % 4 {
        0 => {
            let mut r = ImuReader::from_reader(&text[..], Path::new("imu.txt"), week);
            let mut last = None;
            while let Ok(Some(s)) = r.next_sample(&mut d) {
                let dt = last.map_or(1.0, |l| s.time.seconds_since(l));
                assert!(last.is_none_or(|l| s.time > l), "{s:?}");
                assert!(increment_problem(&s.dtheta, &s.dvel, dt).is_none(), "{s:?}");
                assert!(s.odo_speed.is_none_or(|v| v.is_finite()));
                last = Some(s.time);
            }
        }
        k @ (1 | 2) => {
            let layout = if k == 1 {
                GnssLayout::Cpp
            } else {
                GnssLayout::Matlab
            };
            let mut r = GnssReader::from_reader(&text[..], Path::new("gnss.txt"), week, layout);
            let mut last = None;
            while let Ok(Some(f)) = r.next_fix(&mut d) {
                assert!(last.is_none_or(|l| f.time > l));
                let p = f.pos;
                assert!(
                    position_problem(p.lat_rad.to_degrees(), p.lon_rad.to_degrees(), p.h_m)
                        .is_none(),
                    "{f:?}"
                );
                assert!(f.pos_sd.iter().all(|s| s.is_finite() && *s > 0.0), "{f:?}");
                if let (Some(v), Some(s)) = (f.vel, f.vel_sd) {
                    assert!(velocity_problem(&[v.x, v.y, v.z]).is_none(), "{f:?}");
                    assert!(s.iter().all(|s| s.is_finite() && *s > 0.0), "{f:?}");
                }
                last = Some(f.time);
            }
        }
        _ => {
            let mut r = NavReader::from_reader(&text[..], Path::new("truth.nav"));
            let mut last = None;
            while let Ok(Some(n)) = r.next_record(&mut d) {
                assert!(last.is_none_or(|l| n.time > l));
                assert!(
                    position_problem(n.lat_deg, n.lon_deg, n.h_m).is_none(),
                    "{n:?}"
                );
                assert!(velocity_problem(&n.vel).is_none(), "{n:?}");
                assert!(n.att_deg.iter().all(|a| a.is_finite()), "{n:?}");
                last = Some(n.time);
            }
        }
    }
});
