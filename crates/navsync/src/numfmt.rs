//! Number formatting without allocation: the bottom layer under both
//! [`crate::time`] (`GpsTime::write_sow`) and the text formats
//! ([`crate::io::text`] re-exports these), so that time does not depend on io.
#![warn(missing_docs)]

const DIGIT_PAIRS: &[u8; 200] = b"0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

/// Writes the digits of `v` right-aligned into `tmp` (two at a time) and
/// returns the index of the first digit.
#[inline]
fn digits(mut v: u64, tmp: &mut [u8; 20]) -> usize {
    let mut i = tmp.len();
    while v >= 100 {
        let d = (v % 100) as usize * 2;
        v /= 100;
        i -= 2;
        tmp[i] = DIGIT_PAIRS[d];
        tmp[i + 1] = DIGIT_PAIRS[d + 1];
    }
    if v >= 10 {
        let d = v as usize * 2;
        i -= 2;
        tmp[i] = DIGIT_PAIRS[d];
        tmp[i + 1] = DIGIT_PAIRS[d + 1];
    } else {
        i -= 1;
        tmp[i] = b'0' + v as u8;
    }
    i
}

/// Appends the decimal digits of `v`.
#[inline]
pub fn push_u64(out: &mut Vec<u8>, v: u64) {
    let mut tmp = [0u8; 20];
    let i = digits(v, &mut tmp);
    out.extend_from_slice(&tmp[i..]);
}

/// Appends `v` zero-padded to `width` digits (at most 20).
#[inline]
pub(crate) fn push_u64_padded(out: &mut Vec<u8>, v: u64, width: usize) {
    let mut tmp = [b'0'; 20];
    let i = digits(v, &mut tmp);
    let start = tmp.len() - width.min(20).max(tmp.len() - i);
    out.extend_from_slice(&tmp[start..]);
}

const POW10: [f64; 16] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
];

/// Appends `v` in its shortest form that reads back to the same `f64`
/// (e.g. `2.2899799383470081e-7`, `-0.049`); NaN and infinities as Rust
/// prints them. Every bit is kept (seed 001 §1.5 point 4).
#[inline]
pub fn push_f64(out: &mut Vec<u8>, v: f64) {
    let mut b = zmij::Buffer::new();
    out.extend_from_slice(b.format(v).as_bytes());
}

/// Appends `v` with exactly `decimals` decimals (like `%.{decimals}f`),
/// without allocating. Values too large for the fast path fall back to the
/// standard formatter; non-finite values print as `nan`/`inf`.
#[inline]
pub(crate) fn push_fixed(out: &mut Vec<u8>, v: f64, decimals: usize) {
    let decimals = decimals.min(15);
    let scale = POW10[decimals];
    let scaled = (v * scale).round();
    if !scaled.is_finite() || scaled.abs() >= 9.0e18 {
        use std::io::Write;
        let _ = write!(out, "{v:.decimals$}");
        return;
    }
    let mut n = scaled as i64;
    // A value that rounds to zero prints unsigned ("0.000", not "-0.000").
    if n < 0 {
        out.push(b'-');
        n = -n;
    }
    let n = n as u64;
    let div = scale as u64;
    // Integer digits, the point and the zero-padded fraction assembled in
    // one stack buffer, copied out once.
    let mut buf = [b'0'; 40];
    let mut tmp = [b'0'; 20];
    let i = digits(n / div, &mut tmp);
    let int_len = 20 - i;
    buf[..int_len].copy_from_slice(&tmp[i..]);
    let mut len = int_len;
    if decimals > 0 {
        buf[len] = b'.';
        len += 1;
        let mut ftmp = [b'0'; 20];
        let j = digits(n % div, &mut ftmp);
        let start = 20 - decimals.max(20 - j);
        buf[len..len + decimals].copy_from_slice(&ftmp[start..]);
        len += decimals;
    }
    out.extend_from_slice(&buf[..len]);
}
