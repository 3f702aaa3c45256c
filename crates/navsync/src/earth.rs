//! WGS-84 Earth model: ellipsoid, radii of curvature, normal gravity, Earth
//! and transport rates, and geodetic/ECEF conversions.
//!
//! Sources: NIMA TR8350.2 (WGS-84), 3rd ed., §3 (defining constants) and
//! §4 (normal gravity, eqs 4-1 and 4-3); Groves, *Principles of GNSS,
//! Inertial, and Multisensor Integrated Navigation*, 2nd ed. (2013),
//! eqs 2.105–2.106 (radii), 5.41–5.44 (rates in the local frame),
//! 2.112–2.113 (geodetic/ECEF).
#![warn(missing_docs)]

use nalgebra::{Matrix3, Vector3};

/// WGS-84 semi-major axis (m).
pub const A: f64 = 6_378_137.0;
/// WGS-84 flattening.
pub const F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared, e² = f(2 − f).
pub(crate) const E2: f64 = F * (2.0 - F);
/// WGS-84 semi-minor axis (m).
pub const B: f64 = A * (1.0 - F);
/// Earth rotation rate (rad/s), WGS-84.
pub const OMEGA_E: f64 = 7.292_115e-5;
/// Earth gravitational constant GM (m³/s²), WGS-84.
pub(crate) const GM: f64 = 3.986_004_418e14;
/// Normal gravity at the equator (m/s²), TR8350.2 table 3.4.
pub(crate) const GAMMA_E: f64 = 9.780_325_335_9;
/// Somigliana constant k = (b γ_p)/(a γ_e) − 1, TR8350.2 eq 4-1.
pub(crate) const SOMIGLIANA_K: f64 = 0.001_931_852_652_41;
/// m = ω² a² b / GM, TR8350.2 eq 4-3.
pub(crate) const GRAVITY_M: f64 = OMEGA_E * OMEGA_E * A * A * B / GM;

/// Geodetic position: latitude and longitude in radians, ellipsoidal height
/// in metres.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Geodetic {
    /// Geodetic latitude (rad), positive north.
    pub lat_rad: f64,
    /// Longitude (rad), positive east.
    pub lon_rad: f64,
    /// Height above the WGS-84 ellipsoid (m), positive up.
    pub h_m: f64,
}

impl Geodetic {
    /// From latitude, longitude (rad) and ellipsoidal height (m).
    pub const fn new(lat_rad: f64, lon_rad: f64, h_m: f64) -> Self {
        Geodetic {
            lat_rad,
            lon_rad,
            h_m,
        }
    }

    /// From degrees (latitude, longitude) and metres.
    pub fn from_deg(lat_deg: f64, lon_deg: f64, h_m: f64) -> Self {
        Geodetic::new(lat_deg.to_radians(), lon_deg.to_radians(), h_m)
    }
}

/// Meridian (north–south) and prime-vertical (east–west) radii of
/// curvature (m) at latitude with `sin_lat = sin(lat)`. Groves eqs 2.105–2.106.
#[inline]
pub fn radii(sin_lat: f64) -> (f64, f64) {
    let w2 = 1.0 - E2 * sin_lat * sin_lat;
    let w = w2.sqrt();
    let rn = A / w;
    let rm = A * (1.0 - E2) / (w2 * w);
    (rm, rn)
}

/// Normal gravity magnitude (m/s²) at latitude (via `sin_lat`) and
/// ellipsoidal height: Somigliana's closed form on the ellipsoid
/// (TR8350.2 eq 4-1) with the second-order height correction (eq 4-3).
#[inline]
pub fn gravity(sin_lat: f64, h_m: f64) -> f64 {
    let s2 = sin_lat * sin_lat;
    let g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / (1.0 - E2 * s2).sqrt();
    g0 * (1.0 - 2.0 / A * (1.0 + F + GRAVITY_M - 2.0 * F * s2) * h_m + 3.0 / (A * A) * h_m * h_m)
}

/// Earth rate resolved in NED: ω_ie^n = [Ω cos φ, 0, −Ω sin φ]. Groves eq 5.41.
#[inline]
pub fn omega_ie_n(sin_lat: f64, cos_lat: f64) -> Vector3<f64> {
    Vector3::new(OMEGA_E * cos_lat, 0.0, -OMEGA_E * sin_lat)
}

/// Transport rate ω_en^n = [v_E/(R_N+h), −v_N/(R_M+h), −v_E tan φ/(R_N+h)].
/// Groves eq 5.44.
#[inline]
pub(crate) fn omega_en_n(
    vel_ned: &Vector3<f64>,
    rm_h: f64,
    rn_h: f64,
    tan_lat: f64,
) -> Vector3<f64> {
    Vector3::new(
        vel_ned.y / rn_h,
        -vel_ned.x / rm_h,
        -vel_ned.y * tan_lat / rn_h,
    )
}

/// Local quantities of the Earth model at a point, computed once and shared
/// by the mechanization and the error model.
#[derive(Copy, Clone, Debug)]
pub struct LocalEarth {
    pub(crate) sin_lat: f64,
    pub(crate) cos_lat: f64,
    pub(crate) tan_lat: f64,
    /// R_M + h (m).
    pub(crate) rm_h: f64,
    /// R_N + h (m).
    pub(crate) rn_h: f64,
    /// Normal gravity magnitude (m/s²), positive down.
    pub g: f64,
    /// ω_ie^n (rad/s).
    pub(crate) w_ie: Vector3<f64>,
    /// ω_en^n (rad/s).
    pub(crate) w_en: Vector3<f64>,
}

impl LocalEarth {
    /// Evaluates the model at `pos` with NED velocity `vel`.
    #[inline]
    pub fn new(pos: &Geodetic, vel: &Vector3<f64>) -> Self {
        let (sin_lat, cos_lat) = pos.lat_rad.sin_cos();
        let tan_lat = sin_lat / cos_lat;
        let (rm, rn) = radii(sin_lat);
        let rm_h = rm + pos.h_m;
        let rn_h = rn + pos.h_m;
        LocalEarth {
            sin_lat,
            cos_lat,
            tan_lat,
            rm_h,
            rn_h,
            g: gravity(sin_lat, pos.h_m),
            w_ie: omega_ie_n(sin_lat, cos_lat),
            w_en: omega_en_n(vel, rm_h, rn_h, tan_lat),
        }
    }

    /// ω_in^n = ω_ie^n + ω_en^n.
    #[inline]
    pub(crate) fn w_in(&self) -> Vector3<f64> {
        self.w_ie + self.w_en
    }

    /// Converts a small NED displacement (m) into (Δlat, Δlon, Δh):
    /// the inverse of D_R (KF-GINS algorithm doc, D_R matrix).
    #[inline]
    pub fn ned_to_geodetic_delta(&self, d_ned: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(
            d_ned.x / self.rm_h,
            d_ned.y / (self.rn_h * self.cos_lat),
            -d_ned.z,
        )
    }

    /// NED displacement (m) of a small geodetic difference (D_R).
    #[inline]
    pub fn geodetic_delta_to_ned(&self, dlat: f64, dlon: f64, dh: f64) -> Vector3<f64> {
        Vector3::new(dlat * self.rm_h, dlon * self.rn_h * self.cos_lat, -dh)
    }
}

/// Geodetic → ECEF (m). Groves eq 2.112.
pub fn geodetic_to_ecef(p: &Geodetic) -> Vector3<f64> {
    let (s, c) = p.lat_rad.sin_cos();
    let (sl, cl) = p.lon_rad.sin_cos();
    let rn = A / (1.0 - E2 * s * s).sqrt();
    Vector3::new(
        (rn + p.h_m) * c * cl,
        (rn + p.h_m) * c * sl,
        (rn * (1.0 - E2) + p.h_m) * s,
    )
}

/// ECEF → geodetic by fixed-point iteration on latitude (converges to
/// below 1e-12 rad in a few steps for terrestrial heights). Groves eq 2.113.
pub fn ecef_to_geodetic(r: &Vector3<f64>) -> Geodetic {
    let p = (r.x * r.x + r.y * r.y).sqrt();
    let lon = r.y.atan2(r.x);
    let mut lat = r.z.atan2(p * (1.0 - E2));
    let mut h = 0.0;
    for _ in 0..8 {
        let s = lat.sin();
        let rn = A / (1.0 - E2 * s * s).sqrt();
        // Well conditioned at every latitude (no division by cos φ).
        let (s, c) = lat.sin_cos();
        h = p * c + (r.z + E2 * rn * s) * s - rn;
        let new_lat = r.z.atan2(p * (1.0 - E2 * rn / (rn + h)));
        let done = (new_lat - lat).abs() < 1e-14;
        lat = new_lat;
        if done {
            break;
        }
    }
    Geodetic::new(lat, lon, h)
}

/// Rotation from NED at `p` to ECEF, C_n^e. Groves eq 2.150.
pub fn c_ne(p: &Geodetic) -> Matrix3<f64> {
    let (s, c) = p.lat_rad.sin_cos();
    let (sl, cl) = p.lon_rad.sin_cos();
    Matrix3::new(
        -s * cl,
        -sl,
        -c * cl, //
        -s * sl,
        cl,
        -c * sl, //
        c,
        0.0,
        -s,
    )
}

/// NED offset (m) of `p` from `origin`, exact through ECEF.
pub fn ned_offset(origin: &Geodetic, p: &Geodetic) -> Vector3<f64> {
    c_ne(origin).transpose() * (geodetic_to_ecef(p) - geodetic_to_ecef(origin))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gravity_matches_published_values() {
        // TR8350.2 table 3.4: gamma_e = 9.7803253359, gamma_p = 9.8321849378.
        assert!((gravity(0.0, 0.0) - 9.780_325_335_9).abs() < 1e-10);
        assert!((gravity(1.0, 0.0) - 9.832_184_937_8).abs() < 1e-9);
        // Free-air gradient near the surface is about -3.086e-6 (m/s^2)/m.
        let grad = (gravity(0.5, 100.0) - gravity(0.5, 0.0)) / 100.0;
        assert!((grad + 3.086e-6).abs() < 0.01e-6, "{grad}");
        // Agrees with the KF-GINS series (GRS80 constants) to ~2e-6 m/s^2.
        let s: f64 = 30.4f64.to_radians().sin();
        let s2 = s * s;
        let series = 9.780_326_771_5
            * (1.0
                + 0.005_279_041_4 * s2
                + 0.000_023_271_8 * s2 * s2
                + 0.000_000_126_2 * s2.powi(3));
        assert!((gravity(s, 0.0) - series).abs() < 2e-6);
    }

    #[test]
    fn radii_at_equator_and_pole() {
        let (rm, rn) = radii(0.0);
        assert!((rn - A).abs() < 1e-6);
        assert!((rm - A * (1.0 - E2)).abs() < 1e-6);
        let (rm, rn) = radii(1.0);
        assert!((rm - rn).abs() < 1e-6);
        assert!((rn - A / (1.0 - E2).sqrt()).abs() < 1e-6);
    }

    #[test]
    fn ecef_round_trip() {
        for &(lat, lon, h) in &[
            (30.4447873701, 114.4718632047, 20.9),
            (-45.0, -170.0, 1234.5),
            (89.9, 10.0, -50.0),
            (0.0, 0.0, 0.0),
        ] {
            let g = Geodetic::from_deg(lat, lon, h);
            let back = ecef_to_geodetic(&geodetic_to_ecef(&g));
            assert!((back.lat_rad - g.lat_rad).abs() < 1e-12);
            assert!((back.lon_rad - g.lon_rad).abs() < 1e-12);
            assert!((back.h_m - g.h_m).abs() < 1e-6);
        }
    }

    #[test]
    fn small_offsets_agree_with_radii() {
        let o = Geodetic::from_deg(30.0, 114.0, 50.0);
        let le = LocalEarth::new(&o, &Vector3::zeros());
        let d = Vector3::new(12.0, -7.0, 1.5);
        let dg = le.ned_to_geodetic_delta(&d);
        let p = Geodetic::new(o.lat_rad + dg.x, o.lon_rad + dg.y, o.h_m + dg.z);
        let exact = ned_offset(&o, &p);
        assert!((exact - d).norm() < 1e-4, "{exact} vs {d}");
    }
}
