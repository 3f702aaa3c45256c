//! Attitude representations: Hamilton quaternions `q_nb` (body to
//! navigation), rotation matrices `c_nb`, ZYX Euler angles (roll, pitch,
//! yaw) and rotation vectors.
//!
//! Sources: Groves (2013) eqs 2.22–2.24 (Euler ↔ matrix), 2.34–2.35
//! (quaternion ↔ matrix); Savage, *Strapdown Analytics* (2000) §3.2.2
//! (rotation vector ↔ quaternion, with series near zero).
#![warn(missing_docs)]

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Roll, pitch, yaw (rad), ZYX convention: the body frame is reached from
/// NED by yaw about down, then pitch about the new east, then roll about
/// the new forward.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Euler {
    /// Roll (rad), the last rotation, about body forward (x); positive
    /// right side down.
    pub(crate) roll_rad: f64,
    /// Pitch (rad), about the yawed east axis; positive nose up.
    pub(crate) pitch_rad: f64,
    /// Yaw (rad), heading of body forward from north about down; positive
    /// towards east.
    pub yaw_rad: f64,
}

impl Euler {
    /// From roll, pitch and yaw (rad).
    pub const fn new(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Self {
        Euler {
            roll_rad,
            pitch_rad,
            yaw_rad,
        }
    }

    /// From degrees.
    pub fn from_deg(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> Self {
        Euler::new(
            roll_deg.to_radians(),
            pitch_deg.to_radians(),
            yaw_deg.to_radians(),
        )
    }

    /// As degrees `[roll, pitch, yaw]`.
    pub fn to_deg(self) -> [f64; 3] {
        [
            self.roll_rad.to_degrees(),
            self.pitch_rad.to_degrees(),
            self.yaw_rad.to_degrees(),
        ]
    }
}

/// The skew-symmetric (cross-product) matrix: `skew(a) * b == a × b`.
#[inline]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// C_b^n from ZYX Euler angles. Groves eq 2.24.
pub fn euler_to_dcm(e: &Euler) -> Matrix3<f64> {
    dcm_from_sin_cos(
        e.roll_rad.sin_cos(),
        e.pitch_rad.sin_cos(),
        e.yaw_rad.sin_cos(),
    )
}

/// C_b^n from the (sin, cos) of roll, pitch and yaw (ZYX), for callers
/// that already hold them. Groves eq 2.24.
pub fn dcm_from_sin_cos(
    (sr, cr): (f64, f64),
    (sp, cp): (f64, f64),
    (sy, cy): (f64, f64),
) -> Matrix3<f64> {
    Matrix3::new(
        cp * cy,
        -cr * sy + sr * sp * cy,
        sr * sy + cr * sp * cy,
        cp * sy,
        cr * cy + sr * sp * sy,
        -sr * cy + cr * sp * sy,
        -sp,
        sr * cp,
        cr * cp,
    )
}

/// ω_nb^b from the ZYX Euler-angle rates [roll, pitch, yaw] (rad/s), given
/// the (sin, cos) of roll and pitch. Groves eq 2.56, inverted.
pub fn body_rate_from_euler_rates(
    (sr, cr): (f64, f64),
    (sp, cp): (f64, f64),
    [roll_rate, pitch_rate, yaw_rate]: [f64; 3],
) -> Vector3<f64> {
    Vector3::new(
        roll_rate - yaw_rate * sp,
        pitch_rate * cr + yaw_rate * cp * sr,
        -pitch_rate * sr + yaw_rate * cp * cr,
    )
}

/// ZYX Euler angles from C_b^n; yaw in (−π, π]. At pitch ±90° roll is set
/// to zero and the whole heading goes to yaw. Groves eq 2.22.
pub(crate) fn dcm_to_euler(c: &Matrix3<f64>) -> Euler {
    let pitch = (-c[(2, 0)]).clamp(-1.0, 1.0).asin();
    if c[(2, 0)].abs() < 1.0 - 1e-12 {
        Euler::new(
            c[(2, 1)].atan2(c[(2, 2)]),
            pitch,
            c[(1, 0)].atan2(c[(0, 0)]),
        )
    } else {
        // Gimbal lock: only yaw - roll (or yaw + roll) is defined.
        Euler::new(0.0, pitch, (-c[(0, 1)]).atan2(c[(1, 1)]))
    }
}

/// q_nb from ZYX Euler angles (Hamilton convention).
pub fn euler_to_quat(e: &Euler) -> UnitQuaternion<f64> {
    let (sr, cr) = (0.5 * e.roll_rad).sin_cos();
    let (sp, cp) = (0.5 * e.pitch_rad).sin_cos();
    let (sy, cy) = (0.5 * e.yaw_rad).sin_cos();
    UnitQuaternion::new_normalize(Quaternion::new(
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ))
}

/// ZYX Euler angles from q_nb.
pub(crate) fn quat_to_euler(q: &UnitQuaternion<f64>) -> Euler {
    dcm_to_euler(q.to_rotation_matrix().matrix())
}

/// Quaternion of a rotation vector φ: [cos(|φ|/2), sin(|φ|/2) φ/|φ|], with
/// the Taylor series below 1e-4 rad (Savage 2000, eq 3.2.2.1-8).
#[inline]
pub fn rotvec_to_quat(phi: &Vector3<f64>) -> UnitQuaternion<f64> {
    let a2 = phi.norm_squared();
    let (w, s) = if a2 < 1e-8 {
        // cos(a/2) ≈ 1 − a²/8 + a⁴/384; sin(a/2)/a ≈ 1/2 − a²/48 + a⁴/3840
        (
            1.0 - a2 / 8.0 + a2 * a2 / 384.0,
            0.5 - a2 / 48.0 + a2 * a2 / 3840.0,
        )
    } else {
        let a = a2.sqrt();
        let (sh, ch) = (0.5 * a).sin_cos();
        (ch, sh / a)
    };
    UnitQuaternion::new_unchecked(Quaternion::new(w, s * phi.x, s * phi.y, s * phi.z))
}

/// Rotation vector of a unit quaternion (angle in [0, π]).
pub(crate) fn quat_to_rotvec(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let q = if q.w < 0.0 {
        -q.into_inner()
    } else {
        q.into_inner()
    };
    let v = q.imag();
    let s = v.norm();
    if s < 1e-12 {
        return v * 2.0;
    }
    let angle = 2.0 * s.atan2(q.w);
    v * (angle / s)
}

/// The attitude `q_nb` turned about the navigation frame's vertical by
/// `yaw_rad` (a heading change; roll and pitch relative to the level are
/// kept): q ← R_z(ψ) q.
pub(crate) fn turned_in_yaw(q_nb: &UnitQuaternion<f64>, yaw_rad: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_rad) * q_nb
}

/// Wraps an angle to (−π, π].
#[inline]
pub fn wrap_pi(a: f64) -> f64 {
    let mut x =
        (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
    if x <= -std::f64::consts::PI {
        x += 2.0 * std::f64::consts::PI;
    }
    x
}

/// Wraps an angle in degrees to (−180, 180].
#[inline]
pub(crate) fn wrap_180(deg: f64) -> f64 {
    wrap_pi(deg.to_radians()).to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    /// Turning in yaw changes the heading by the angle and keeps roll and
    /// pitch: (5°, 10°, 30°) turned by 20° is (5°, 10°, 50°).
    #[test]
    fn turning_in_yaw_keeps_roll_and_pitch() {
        let d = |x: f64| x.to_radians();
        let q = euler_to_quat(&Euler::new(d(5.0), d(10.0), d(30.0)));
        let e = quat_to_euler(&turned_in_yaw(&q, d(20.0)));
        assert!((e.roll_rad - d(5.0)).abs() < 1e-12, "{e:?}");
        assert!((e.pitch_rad - d(10.0)).abs() < 1e-12, "{e:?}");
        assert!((e.yaw_rad - d(50.0)).abs() < 1e-12, "{e:?}");
    }

    #[test]
    fn euler_dcm_quat_agree() {
        for &(r, p, y) in &[
            (0.0, 0.0, 45.0),
            (10.0, -20.0, 170.0),
            (-179.0, 89.0, -90.0),
            (5.0, 3.0, -179.5),
        ] {
            let e = Euler::from_deg(r, p, y);
            let c = euler_to_dcm(&e);
            let q = euler_to_quat(&e);
            assert!((q.to_rotation_matrix().matrix() - c).abs().max() < 1e-12);
            // nalgebra's own ZYX construction is the same rotation
            let qn = UnitQuaternion::from_euler_angles(e.roll_rad, e.pitch_rad, e.yaw_rad);
            assert!(q.angle_to(&qn) < 1e-12);
            let back = dcm_to_euler(&c);
            assert!((back.roll_rad - e.roll_rad).abs() < 1e-9);
            assert!((back.pitch_rad - e.pitch_rad).abs() < 1e-9);
            assert!(wrap_pi(back.yaw_rad - e.yaw_rad).abs() < 1e-9);
        }
    }

    #[test]
    fn yaw_rotates_north_to_east() {
        let c = euler_to_dcm(&Euler::new(0.0, 0.0, FRAC_PI_2));
        // body forward points east
        let f = c * Vector3::x();
        assert!((f - Vector3::y()).norm() < 1e-12);
    }

    #[test]
    fn rotvec_round_trip_and_small_angles() {
        for v in [
            Vector3::new(0.1, -0.2, 0.3),
            Vector3::new(1e-6, 2e-7, -3e-6),
            Vector3::new(0.0, 0.0, 3.0),
            Vector3::zeros(),
        ] {
            let q = rotvec_to_quat(&v);
            assert!((q.norm() - 1.0).abs() < 1e-14);
            assert!((quat_to_rotvec(&q) - v).norm() < 1e-12);
            let qn = UnitQuaternion::from_scaled_axis(v);
            assert!(q.angle_to(&qn) < 1e-12);
        }
    }

    #[test]
    fn gimbal_lock_keeps_heading() {
        let e = Euler::from_deg(0.0, 90.0, 30.0);
        let back = dcm_to_euler(&euler_to_dcm(&e));
        assert!((back.pitch_rad - FRAC_PI_2).abs() < 1e-6);
        assert!((back.yaw_rad - e.yaw_rad).abs() < 1e-6);
    }

    #[test]
    fn wrapping() {
        assert!((wrap_180(190.0) + 170.0).abs() < 1e-9);
        assert!((wrap_180(-180.0) - 180.0).abs() < 1e-9);
        assert!((wrap_180(359.0) + 1.0).abs() < 1e-9);
    }
}
