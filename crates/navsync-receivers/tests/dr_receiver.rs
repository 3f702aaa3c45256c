//! A u-blox sensor-fusion (dead-reckoning) receiver's real log: NAV-PVAT
//! and NAV-ATT, no NAV-PVT (shared data `real-logs/ublox-dr-navpvat`,
//! from pyubx2's test data, BSD 3-clause).

use navsync::Diagnostics;
use navsync::io::heading::{HeadingSource, read_headings};
use navsync::io::kfgins::{GnssLayout, GnssReader};
use navsync::testfiles::TestDir;
use navsync_receivers::convert::{ConvertOptions, InputFormat, convert};
use navsync_receivers::fixes::{FUSED_CORRELATION_TIME_S, fused_sd_factor};

#[test]
fn fused_solution_converts_to_fixes_and_vehicle_headings() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-logs/ublox-dr-navpvat/pygpsdata-SF-calibration.log");
    if !path.is_file() {
        eprintln!("skipped: {} not found", path.display());
        return;
    }
    let out = TestDir::new("dr-receiver");
    let s = convert(InputFormat::Ubx, &path, &out, &ConvertOptions::default()).unwrap();
    assert_eq!(s.frames.get("UBX NAV-PVAT"), Some(&527), "{:?}", s.frames);
    assert_eq!(s.frames.get("UBX NAV-ATT"), Some(&527), "{:?}", s.frames);
    assert!(s.gnss_fixes >= 500, "{} fixes", s.gnss_fixes);
    assert!(
        s.headings >= 500,
        "{} headings {:?}",
        s.headings,
        s.heading_drops
    );
    // The summary says what the fixes are.
    assert!(s.gnss_source.contains("FUSED"), "{}", s.gnss_source);
    let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(json.contains("dead-reckoning solution"), "{json}");
    // σ: the receiver's hAcc × the fused factor, never below it.
    let k = fused_sd_factor(1.0, FUSED_CORRELATION_TIME_S);
    assert!((k - 20f64.sqrt()).abs() < 0.05, "{k}");
    let mut d = Diagnostics::default();
    let mut r = GnssReader::open(&out.join("gnss.txt"), 0, GnssLayout::Cpp).unwrap();
    let mut n = 0;
    let mut last = None;
    while let Some(f) = r.next_fix(&mut d).unwrap() {
        assert!(f.pos_sd[0] > 0.1 && f.pos_sd[0] < 100.0, "{:?}", f.pos_sd);
        // Near 51.26° N 0.57° W (the README).
        assert!((f.pos.lat_rad.to_degrees() - 51.26).abs() < 0.1);
        assert!((f.pos.lon_rad.to_degrees() + 0.57).abs() < 0.1);
        if let Some(t) = last {
            assert!(f.time > t);
        }
        last = Some(f.time);
        n += 1;
    }
    assert_eq!(n, s.gnss_fixes);
    let h = read_headings(&out.join("heading.txt"), 0, &mut d).unwrap();
    assert!(h.iter().all(|o| o.source == HeadingSource::Vehicle));
    assert!(d.is_empty(), "{d:?}");
}
