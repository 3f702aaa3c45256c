//! Fuzzes the ArduPilot DataFlash reader (`navsync_receivers::dataflash`):
//! raw bytes (mode byte even), or the FMT messages of the 2014 and current
//! layouts the converter reads followed by messages of those types with
//! fuzzed payloads, spliced with raw bytes (so the extraction of IMU, GPS,
//! GPA/UBX3, EKF and AHR2 is reached). Checks beyond "no panic": IMU
//! samples finite; fixes finite, plausible, strictly increasing in time,
//! with positive σ; the estimate finite; the boot → GPS relation finite.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync::Diagnostics;
use navsync_receivers::autopilot::BootToGps;
use navsync_receivers::dataflash::{HEAD, read_dataflash};
use navsync_receivers::testdataflash::{DataFlashWriter, LAYOUT_2014, LAYOUT_CURRENT};

fuzz_target!(|data: &[u8]| {
    if data.is_empty() {
        return;
    }
    let (mode, rest) = (data[0], &data[1..]);
    let bytes = if mode & 1 == 0 {
        rest.to_vec()
    } else {
        let layouts: Vec<_> = LAYOUT_2014.iter().chain(&LAYOUT_CURRENT).collect();
        let mut w = DataFlashWriter::new();
        for (t, n, f, l) in &layouts {
            w.fmt(*t, n, f, l);
        }
        let mut out = w.bytes;
        // [selector, payload of that layout's length…, garbage_len, garbage…]*
        let lens: Vec<(u8, usize)> = {
            let mut probe = DataFlashWriter::new();
            layouts
                .iter()
                .map(|(t, n, f, l)| {
                    probe.fmt(*t, n, f, l);
                    let before = probe.bytes.len();
                    probe.msg(n, &[]);
                    (*t, probe.bytes.len() - before - 3)
                })
                .collect()
        };
        let mut i = 0;
        while i < rest.len() {
            let (t, len) = lens[rest[i] as usize % lens.len()];
            let len = len.min(rest.len() - i - 1);
            out.extend_from_slice(&HEAD);
            out.push(t);
            out.extend_from_slice(&rest[i + 1..i + 1 + len]);
            i += 1 + len;
            if let Some(&g) = rest.get(i) {
                let g = (g as usize % 4).min(rest.len() - i - 1);
                out.extend_from_slice(&rest[i + 1..i + 1 + g]);
                i += 1 + g;
            }
        }
        out
    };
    let mut diag = Diagnostics::with_cap(100);
    let r = read_dataflash(&bytes, Path::new("fuzz.BIN"), [5.0, 5.0, 10.0], &mut diag);
    for s in &r.imu {
        assert!(s.values.iter().all(|v| v.is_finite()));
    }
    for w in r.fixes.windows(2) {
        assert!(w[0].time < w[1].time);
    }
    for f in &r.fixes {
        assert!(f.lat_deg.abs() <= 90.0 && f.lon_deg.abs() <= 180.0 && f.h_m.is_finite());
        assert!(f.sd_m.iter().all(|s| s.is_finite() && *s > 0.0));
    }
    for e in &r.estimate {
        assert!(e.h_m.is_finite() && e.vel_ned_mps.iter().chain(&e.att_deg).all(|v| v.is_finite()));
    }
    if let Some(map) = BootToGps::from_fixes(&r.fixes) {
        assert!(map.clock_error_ppm().is_finite());
        for f in &r.fixes {
            let _ = map.gps(f.arrival_us);
        }
    }
});
