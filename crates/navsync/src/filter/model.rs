//! The continuous error model F and noise q of the 21-state INS error
//! state, integrated over a propagation window.
//!
//! Derived from the KF-GINS algorithm doc §3.3 (error differential
//! equations for δr, δv, φ and the Gauss-Markov IMU errors) with this
//! crate's sign convention δx = x̂ − x for every state, so that
//! δω_ib = −δb_g − diag(ω_ib) δs_g and δf = −δb_a − diag(f) δs_a. The
//! position rows are differentiated directly from
//! δr = [(R_M+h) δφ, (R_N+h) cos φ δλ, −δh].

use nalgebra::{Matrix3, Vector3};

use super::dense::Mat;
use super::{ImuNoise, StateLayout, Window, idx};
use crate::attitude::skew;
use crate::earth::{LocalEarth, OMEGA_E};

/// Position/velocity partials of the local Earth quantities.
pub(crate) struct ErrorPartials {
    /// ∂ω_ie^n/∂δr.
    pub(crate) w_ie_r: Matrix3<f64>,
    /// ∂ω_en^n/∂δr.
    pub(crate) w_en_r: Matrix3<f64>,
    /// ∂ω_en^n/∂δv.
    pub(crate) w_en_v: Matrix3<f64>,
    /// F_rr: d(δr)/dt with respect to δr.
    pub(crate) f_rr: Matrix3<f64>,
    /// F_vr and F_vv.
    pub(crate) f_vr: Matrix3<f64>,
    pub(crate) f_vv: Matrix3<f64>,
}

/// Partials at a point with NED velocity `v` (KF-GINS doc §3.3, δω_ie^n,
/// δω_en^n, δg_p^n; δh = −δr_D, δφ = δr_N/(R_M+h)).
pub(crate) fn partials(le: &LocalEarth, v: &Vector3<f64>) -> ErrorPartials {
    let (vn, ve, vd) = (v.x, v.y, v.z);
    let rm = le.rm_h;
    let rn = le.rn_h;
    let tan = le.tan_lat;
    let cos2 = le.cos_lat * le.cos_lat;

    let w_ie_r = Matrix3::new(
        -OMEGA_E * le.sin_lat / rm,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        -OMEGA_E * le.cos_lat / rm,
        0.0,
        0.0,
    );
    let w_en_r = Matrix3::new(
        0.0,
        0.0,
        ve / (rn * rn),
        0.0,
        0.0,
        -vn / (rm * rm),
        -ve / (rm * rn * cos2),
        0.0,
        -ve * tan / (rn * rn),
    );
    let w_en_v = Matrix3::new(0.0, 1.0 / rn, 0.0, -1.0 / rm, 0.0, 0.0, 0.0, -tan / rn, 0.0);

    // d/dt of [(R_M+h)δφ, (R_N+h)cosφ δλ, −δh] (radius rates neglected).
    let f_rr = Matrix3::new(
        -vd / rm,
        0.0,
        vn / rm,
        ve * tan / rm,
        -vd / rn - vn * tan / rm,
        ve / rn,
        0.0,
        0.0,
        0.0,
    );

    // δv̇ = f^n×φ + C δf − (2ω_ie+ω_en)×δv + v×(2δω_ie+δω_en) + δg
    let sv = skew(v);
    // Free-air gradient ∂g/∂h ≈ −2g/(√(R_M R_N) + h), and δh = −δr_D.
    let mut g_r = Matrix3::zeros();
    g_r[(2, 2)] = 2.0 * le.g / (le.rm_h * le.rn_h).sqrt();
    let f_vr = sv * (2.0 * w_ie_r + w_en_r) + g_r;
    let f_vv = -skew(&(2.0 * le.w_ie + le.w_en)) + sv * w_en_v;

    ErrorPartials {
        w_ie_r,
        w_en_r,
        w_en_v,
        f_rr,
        f_vr,
        f_vv,
    }
}

/// Fills `a` (n × n) with A = ∫F dt over window `w`, the slowly varying
/// terms evaluated at the window's end (`le`, `v`). Gauss-Markov rows get
/// −Δt/T. Extra states have zero rows. Only the structurally nonzero
/// blocks are written: `a` must start zeroed and be reused.
pub(crate) fn fill_transition(
    a: &mut Mat,
    w: &Window,
    le: &LocalEarth,
    v: &Vector3<f64>,
    corr_time_s: f64,
    layout: &StateLayout,
) {
    let dt = w.dt;
    let p = partials(le, v);
    use idx::*;
    a.set_block3(POS, POS, &(p.f_rr * dt));
    a.set_block3(POS, VEL, &(Matrix3::identity() * dt));

    a.set_block3(VEL, POS, &(p.f_vr * dt));
    a.set_block3(VEL, VEL, &(p.f_vv * dt));
    a.set_block3(VEL, ATT, &skew(&w.f_n_dt));
    a.set_block3(VEL, BA, &(-w.c_dt));
    a.set_block3(VEL, SA, &(-w.c_diag_dv));

    // φ̇ = −ω_in×φ + δω_in − C δω_ib
    a.set_block3(ATT, POS, &((p.w_ie_r + p.w_en_r) * dt));
    a.set_block3(ATT, VEL, &(p.w_en_v * dt));
    a.set_block3(ATT, ATT, &(-skew(&le.w_in()) * dt));
    a.set_block3(ATT, BG, &w.c_dt);
    a.set_block3(ATT, SG, &w.c_diag_dth);

    let decay = -dt / corr_time_s;
    for i in BG..CORE {
        a.set(i, i, decay);
    }
    for e in &layout.extras {
        if let Some(tau) = e.corr_time_s {
            a.set(e.index, e.index, -dt / tau);
        }
    }
    // Misalignments (random constants): δω_ib = −J(ω) δm_g, δf = −J(f) δm_a,
    // entering like the scale factors above.
    if let Some(m) = layout.misalign {
        for r in 0..3 {
            for c in 0..6 {
                a.set(ATT + r, m + c, w.c_j_dth[(r, c)]);
                a.set(VEL + r, m + 6 + c, -w.c_j_dv[(r, c)]);
            }
        }
    }
}

/// Fills `q` (n × n) with the window's process noise G q Gᵀ Δt
/// (KF-GINS doc §3.4), using the mean attitude over the window. Q is block
/// diagonal; only those blocks are written (`q` must start zeroed).
pub(crate) fn fill_noise(q: &mut Mat, w: &Window, noise: &ImuNoise, layout: &StateLayout) {
    let dt = w.dt;
    let c = w.c_dt / dt;
    let vrw2 = Matrix3::from_diagonal(&noise.vrw.component_mul(&noise.vrw));
    let arw2 = Matrix3::from_diagonal(&noise.arw.component_mul(&noise.arw));
    use idx::*;
    q.set_block3(VEL, VEL, &(c * vrw2 * c.transpose() * dt));
    q.set_block3(ATT, ATT, &(c * arw2 * c.transpose() * dt));
    let gm = |sd: &Vector3<f64>, start: usize, q: &mut Mat| {
        for i in 0..3 {
            q.set(
                start + i,
                start + i,
                2.0 * sd[i] * sd[i] / noise.corr_time_s * dt,
            );
        }
    };
    gm(&noise.gyro_bias_sd, BG, q);
    gm(&noise.accel_bias_sd, BA, q);
    gm(&noise.gyro_scale_sd, SG, q);
    gm(&noise.accel_scale_sd, SA, q);
    for e in &layout.extras {
        q.set(e.index, e.index, e.random_walk_psd * dt);
    }
}
