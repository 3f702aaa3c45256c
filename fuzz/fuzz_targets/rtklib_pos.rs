//! Fuzzes the RTKLIB `.pos` reader: raw text, or a real llh / xyz column
//! header (week-tow or calendar time) followed by lines of fuzzed fields
//! drawn from the characters such files hold. Beyond "no panic": every
//! fix it returns has finite values, positive σ and increasing times.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync::Diagnostics;
use navsync::io::rtklib::PosReader;

const HEADERS: [&str; 4] = [
    "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n",
    "%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio\n",
    "%  GPST  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)      sdvn     sdve     sdvu    sdvne    sdveu    sdvun\n",
    "%  GPST      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio  vx(m/s)  vy(m/s)  vz(m/s)  sdvx  sdvy  sdvz  sdvxy  sdvyz  sdvzx\n",
];
const ALPHABET: &[u8] = b"0123456789.-/: e%#\n\t,";
const SEEDS: [&str; 6] = [
    "2300 100000.000",
    "2024/02/05 03:46:40.000",
    "30.444787370",
    "-2267810.1234",
    "0.0030",
    "1",
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
        text.extend_from_slice(HEADERS[(mode as usize >> 1) % HEADERS.len()].as_bytes());
        for &b in rest {
            if b & 0x80 != 0 {
                text.extend_from_slice(SEEDS[b as usize % SEEDS.len()].as_bytes());
                text.push(b' ');
            } else {
                text.push(ALPHABET[b as usize % ALPHABET.len()]);
            }
        }
    }
    let mut r = PosReader::from_reader(&text[..], Path::new("fuzz.pos"), (mode >> 4) as i64 * 700);
    r.max_q = 1 + (mode >> 5) % 6;
    let mut d = Diagnostics::with_cap(16);
    let mut last = None;
    while let Ok(Some(f)) = r.next_fix(&mut d) {
        assert!(f.pos.lat_rad.is_finite() && f.pos.lon_rad.is_finite() && f.pos.h_m.is_finite());
        assert!(
            f.pos_sd.iter().all(|s| s.is_finite() && *s > 0.0),
            "{:?}",
            f.pos_sd
        );
        if let (Some(v), Some(s)) = (f.vel, f.vel_sd) {
            assert!(v.iter().chain(s.iter()).all(|x| x.is_finite()));
        }
        assert!(last.is_none_or(|l| f.time > l));
        last = Some(f.time);
    }
    let _ = r.q_summary();
});
