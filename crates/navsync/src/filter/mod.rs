//! The error-state (indirect, closed-loop) Kalman filter.
//!
//! Error state (KF-GINS algorithm doc §3.2, 21 states), every error defined
//! as *estimate minus truth*:
//! `[δr^n (m, NED), δv^n (m/s), φ (rad, φ-angle: Ĉ_b^n = (I − φ×) C_b^n),
//!   δb_g (rad/s), δb_a (m/s²), δs_g, δs_a]`, followed by optional extra
//! states (e.g. the IMU–GNSS time offset) appended by a `StateLayout`.
//!
//! Propagation does not run at the IMU rate: the mechanization hands each
//! step's quantities to a `Window` which sums them (Σ C_b^n Δt, Σ Δv_f^n,
//! Σ C_b^n diag(Δv), Σ C_b^n diag(Δθ)); every `cov_step` seconds, and always
//! before a measurement, the window's A = ∫F dt gives
//! Φ = I + A + A²/2 and P ← Φ (P + Q/2) Φᵀ + Q/2 (the trapezoidal noise
//! integration of the KF-GINS doc, §3.4). First-order terms are exact
//! integrals over the window; the window only truncates terms of third
//! order in its length and second order in the variation of F within it.
//!
//! Measurement updates use the Joseph form (KF-GINS doc eq for P_k) with
//! chi-square innovation gating; the covariance is kept symmetric and its
//! positive definiteness is checked after every update.

#![warn(missing_docs)]

pub mod dense;
pub mod gnss;
pub mod heading;
pub(crate) mod model;
pub mod nhc;
pub mod standstill;
#[cfg(test)]
mod tests;

use nalgebra::{Matrix3, SMatrix, Vector3};

use crate::earth::LocalEarth;
use crate::error::Error;
use crate::ins::{ImuErrors, NavState, StepInfo};
use crate::time::GpsTime;
use dense::{Mat, RowPattern};

// The IMU noise model and the initial σ are base-layer types (io reads them).
pub use crate::types::{ImuNoise, InitialStd};

/// Largest supported number of error states.
pub(crate) const MAX_STATES: usize = 40;

/// Indices of the 21 core error states.
pub(crate) mod idx {
    pub(crate) const POS: usize = 0;
    pub(crate) const VEL: usize = 3;
    pub(crate) const ATT: usize = 6;
    pub(crate) const BG: usize = 9;
    pub(crate) const BA: usize = 12;
    pub(crate) const SG: usize = 15;
    pub(crate) const SA: usize = 18;
    /// Number of core states.
    pub(crate) const CORE: usize = 21;
}

/// An extra state appended after the 21 core states: a random walk with
/// the given power spectral density (units²/s) or, with a correlation
/// time τ, a first-order Gauss–Markov process ẋ = −x/τ + w with that
/// driving-noise density (2σ²/τ for a steady-state σ; Brown & Hwang,
/// *Introduction to Random Signals and Applied Kalman Filtering*, 4th ed.,
/// §4.2).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ExtraState {
    pub name: &'static str,
    pub(crate) index: usize,
    pub(crate) random_walk_psd: f64,
    pub corr_time_s: Option<f64>,
}

/// The state vector's layout: the 21 core states and any extras.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct StateLayout {
    pub(crate) extras: Vec<ExtraState>,
    /// First index of the 12 misalignment states (6 gyro, then 6
    /// accelerometer), when estimated.
    pub(crate) misalign: Option<usize>,
}

/// Names of the misalignment states (see [`crate::ins::ImuErrors`]).
const MISALIGN_NAMES: [&str; 12] = [
    "gyro_misalign_xy",
    "gyro_misalign_xz",
    "gyro_misalign_yx",
    "gyro_misalign_yz",
    "gyro_misalign_zx",
    "gyro_misalign_zy",
    "accel_misalign_xy",
    "accel_misalign_xz",
    "accel_misalign_yx",
    "accel_misalign_yz",
    "accel_misalign_zx",
    "accel_misalign_zy",
];

impl StateLayout {
    /// The name of state `i`, for messages (KF-GINS's 21-state order,
    /// then the extras by name).
    pub(crate) fn state_name(&self, i: usize) -> String {
        const CORE: [&str; 7] = [
            "position",
            "velocity",
            "attitude",
            "gyro bias",
            "accelerometer bias",
            "gyro scale",
            "accelerometer scale",
        ];
        const AXES: [[&str; 3]; 2] = [["north", "east", "down"], ["x", "y", "z"]];
        if i < idx::CORE {
            let axes = if i < idx::ATT { AXES[0] } else { AXES[1] };
            let axis = if (idx::ATT..idx::BG).contains(&i) {
                ["roll", "pitch", "yaw"][i % 3]
            } else {
                axes[i % 3]
            };
            return format!("{} {axis} (state {i})", CORE[i / 3]);
        }
        match self.extras.iter().find(|e| e.index == i) {
            Some(e) => format!("{} (state {i})", e.name),
            None => format!("state {i}"),
        }
    }

    /// Total number of states.
    pub fn n(&self) -> usize {
        idx::CORE + self.extras.len()
    }

    /// Appends an extra state and returns its index.
    pub fn add(&mut self, name: &'static str, random_walk_psd: f64) -> usize {
        let index = self.n();
        self.extras.push(ExtraState {
            name,
            index,
            random_walk_psd,
            corr_time_s: None,
        });
        index
    }

    /// Appends a first-order Gauss–Markov state with steady-state σ `sd`
    /// and correlation time `corr_time_s`, and returns its index.
    pub(crate) fn add_gauss_markov(
        &mut self,
        name: &'static str,
        sd: f64,
        corr_time_s: f64,
    ) -> usize {
        let index = self.add(name, 2.0 * sd * sd / corr_time_s);
        if let Some(e) = self.extras.last_mut() {
            e.corr_time_s = Some(corr_time_s);
        }
        index
    }

    /// Appends the 12 axis-misalignment states (random constants) and
    /// returns the first index.
    pub(crate) fn add_misalignment(&mut self) -> usize {
        let first = self.n();
        for name in MISALIGN_NAMES {
            self.add(name, 0.0);
        }
        self.misalign = Some(first);
        first
    }

    /// Index of the extra state called `name`.
    pub(crate) fn index_of(&self, name: &str) -> Option<usize> {
        self.extras.iter().find(|e| e.name == name).map(|e| e.index)
    }
}

/// Sums over the mechanization steps since the last covariance propagation.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Window {
    /// Total duration (s).
    pub(crate) dt: f64,
    /// Σ C_b^n Δt.
    pub(crate) c_dt: Matrix3<f64>,
    /// Σ Δv_f^n: the specific force integrated in NED.
    pub(crate) f_n_dt: Vector3<f64>,
    /// Σ C_b^n diag(Δv^b).
    pub(crate) c_diag_dv: Matrix3<f64>,
    /// Σ C_b^n diag(Δθ^b).
    pub(crate) c_diag_dth: Matrix3<f64>,
    /// Σ C_b^n J(Δθ^b) and Σ C_b^n J(Δv^b), J(v) = ∂(M v)/∂m (3 × 6):
    /// only summed when misalignments are estimated.
    pub(crate) c_j_dth: SMatrix<f64, 3, 6>,
    pub(crate) c_j_dv: SMatrix<f64, 3, 6>,
}

/// J(v) = ∂(M v)/∂m for the off-diagonal M of [`crate::ins::ImuErrors`].
#[inline]
pub(crate) fn misalign_jacobian(v: &Vector3<f64>) -> SMatrix<f64, 3, 6> {
    let mut j = SMatrix::<f64, 3, 6>::zeros();
    j[(0, 0)] = v.y;
    j[(0, 1)] = v.z;
    j[(1, 2)] = v.x;
    j[(1, 3)] = v.z;
    j[(2, 4)] = v.x;
    j[(2, 5)] = v.y;
    j
}

impl Window {
    /// The misalignment sums of one step.
    #[inline]
    pub(crate) fn add_misalign(&mut self, s: &StepInfo) {
        self.c_j_dth += s.c_nb * misalign_jacobian(&s.inc.dtheta);
        self.c_j_dv += s.c_nb * misalign_jacobian(&s.inc.dvel);
    }

    #[inline]
    pub fn add(&mut self, s: &StepInfo) {
        self.dt += s.dt;
        self.c_dt += s.c_nb * s.dt;
        self.f_n_dt += s.dv_f_n;
        let dv = s.inc.dvel;
        let dth = s.inc.dtheta;
        for j in 0..3 {
            for i in 0..3 {
                self.c_diag_dv[(i, j)] += s.c_nb[(i, j)] * dv[j];
                self.c_diag_dth[(i, j)] += s.c_nb[(i, j)] * dth[j];
            }
        }
    }
}

/// A linearised observation: innovation `z` (predicted minus measured),
/// Jacobian `h` (m × n, row-major) and noise covariance `r` (m × m).
#[derive(Clone, Debug)]
pub struct Observation {
    /// What is observed (`gnss-position`, `gnss-velocity`, `nhc`, `odometer`,
    /// `heading`, `zupt`, `zaru`), for messages.
    pub kind: &'static str,
    /// Innovation, predicted minus measured (m entries).
    pub z: Vec<f64>,
    /// Jacobian of the observation w.r.t. the error state (m × n).
    pub h: Mat,
    /// Measurement noise covariance (m × m).
    pub r: Mat,
}

impl Observation {
    /// An empty observation of dimension `m` for `n` states.
    pub fn new(kind: &'static str, m: usize, n: usize) -> Self {
        Observation {
            kind,
            z: vec![0.0; m],
            h: Mat::zeros(m, n),
            r: Mat::zeros(m, m),
        }
    }

    pub(crate) fn dim(&self) -> usize {
        self.z.len()
    }
}

/// The result of one measurement update.
#[derive(Clone, Debug)]
pub(crate) struct UpdateOutcome {
    /// Normalised innovation squared zᵀ S⁻¹ z.
    pub nis: f64,
    /// False when the chi-square gate rejected the measurement.
    pub accepted: bool,
    /// The estimated error state (zeros when rejected).
    pub dx: Vec<f64>,
}

/// The error-state Kalman filter: covariance, noise model and the pending
/// propagation window. The error-state mean is always zero between updates
/// (closed-loop feedback), so only P is kept.
#[derive(Clone, Debug)]
pub(crate) struct ErrorStateFilter {
    layout: StateLayout,
    n: usize,
    p: Mat,
    noise: ImuNoise,
    window: Window,
    // scratch
    a: Mat,
    q: Mat,
    phi: Vec<f64>,
    /// Diagonal of Φ on the states after the navigation errors.
    phi_diag: Vec<f64>,
    t: Vec<f64>,
    /// The forward run's nodes for the smoother, when recorded.
    track: Option<Box<NodeTrack>>,
}

/// One node of the forward run, as the fixed-interval smoother needs it
/// ([`crate::smoother`]): the transition from the previous node, the
/// covariance before and after this node's corrections, and the sum of
/// the corrections fed back here.
#[derive(Clone, Debug)]
pub(crate) struct SmootherNode {
    pub time: GpsTime,
    /// Φ from the previous node to this one (identity for the first).
    pub(crate) phi_in: Mat,
    /// P just before this node's corrections (equal to `p_plus` without).
    pub(crate) p_minus: Mat,
    /// P after them.
    pub(crate) p_plus: Mat,
    /// Σ of the error states fed back at this node (closed loop: the
    /// nominal state after the node is the one before it minus this).
    pub dx: Vec<f64>,
}

/// Records [`SmootherNode`]s: one at every epoch with corrections, and one
/// at least every `interval_s` between them (the smoother's output is
/// interpolated between nodes).
#[derive(Clone, Debug)]
struct NodeTrack {
    interval_s: f64,
    phi_acc: Mat,
    last_node: Option<GpsTime>,
    /// The node being built: time, P before its first correction, Σ dx.
    open: Option<(GpsTime, Mat, Vec<f64>)>,
    closed: Vec<SmootherNode>,
}

impl NodeTrack {
    fn emit(&mut self, time: GpsTime, p_minus: Mat, p_plus: &Mat, dx: Vec<f64>) {
        let n = p_plus.rows;
        let phi_in = std::mem::replace(&mut self.phi_acc, Mat::identity(n));
        self.closed.push(SmootherNode {
            time,
            phi_in,
            p_minus,
            p_plus: p_plus.clone(),
            dx,
        });
        self.last_node = Some(time);
    }

    fn close_open(&mut self, p: &Mat) {
        if let Some((t, p_minus, dx)) = self.open.take() {
            self.emit(t, p_minus, p, dx);
        }
    }

    fn open_at(&mut self, time: GpsTime, p: &Mat) -> &mut Vec<f64> {
        if self.open.as_ref().is_some_and(|(t, _, _)| *t != time) {
            self.close_open(p);
        }
        let n = p.rows;
        &mut self
            .open
            .get_or_insert_with(|| (time, p.clone(), vec![0.0; n]))
            .2
    }
}

impl ErrorStateFilter {
    /// A filter with diagonal initial covariance from `init_std`; extra
    /// states start with the variances in `extra_var` (same order as
    /// `layout.extras`).
    pub(crate) fn new(
        layout: StateLayout,
        noise: ImuNoise,
        init_std: &InitialStd,
        extra_var: &[f64],
    ) -> Self {
        let n = layout.n();
        assert!(n <= MAX_STATES, "at most {MAX_STATES} error states");
        let mut p = Mat::zeros(n, n);
        let blocks = [
            (idx::POS, init_std.pos),
            (idx::VEL, init_std.vel),
            (idx::ATT, init_std.att),
            (idx::BG, init_std.gyro_bias),
            (idx::BA, init_std.accel_bias),
            (idx::SG, init_std.gyro_scale),
            (idx::SA, init_std.accel_scale),
        ];
        for (start, sd) in blocks {
            for i in 0..3 {
                p.set(start + i, start + i, sd[i] * sd[i]);
            }
        }
        for (e, &v) in layout.extras.iter().zip(extra_var) {
            p.set(e.index, e.index, v);
        }
        ErrorStateFilter {
            layout,
            n,
            p,
            noise,
            window: Window::default(),
            a: Mat::zeros(n, n),
            q: Mat::zeros(n, n),
            phi: vec![0.0; n * n],
            phi_diag: vec![1.0; n],
            t: vec![0.0; 9 * n],
            track: None,
        }
    }

    /// Starts recording [`SmootherNode`]s, at least one every `interval_s`,
    /// with a first node now.
    pub(crate) fn record_nodes(&mut self, time: GpsTime, interval_s: f64) {
        let mut track = NodeTrack {
            interval_s,
            phi_acc: Mat::identity(self.n),
            last_node: None,
            open: None,
            closed: Vec::new(),
        };
        track.emit(time, self.p.clone(), &self.p, vec![0.0; self.n]);
        self.track = Some(Box::new(track));
    }

    /// The nodes completed since the last call (empty unless recording).
    pub(crate) fn take_nodes(&mut self) -> Vec<SmootherNode> {
        self.track
            .as_mut()
            .map(|t| std::mem::take(&mut t.closed))
            .unwrap_or_default()
    }

    /// Ends the recording: the node being built is completed, and a last
    /// node is placed at `time` (after propagating the pending window).
    pub(crate) fn finish_nodes(&mut self, nav: &NavState) {
        self.propagate(nav);
        if let Some(t) = self.track.as_mut() {
            t.close_open(&self.p);
            if t.last_node.is_none_or(|l| l < nav.time) {
                t.emit(nav.time, self.p.clone(), &self.p, vec![0.0; self.n]);
            }
        }
    }

    /// Records a change of the nominal state made outside a Kalman update
    /// (a re-initialisation), as the error state `dx` it removed, before
    /// the caller changes P (a no-op unless recording).
    pub(crate) fn record_correction(&mut self, time: GpsTime, dx: &[f64]) {
        if let Some(t) = self.track.as_mut() {
            for (a, b) in t.open_at(time, &self.p).iter_mut().zip(dx) {
                *a += b;
            }
        }
    }

    pub(crate) fn layout(&self) -> &StateLayout {
        &self.layout
    }

    /// Number of states.
    pub(crate) fn n(&self) -> usize {
        self.n
    }

    /// The covariance (valid after [`Self::propagate`]).
    pub(crate) fn covariance(&self) -> &Mat {
        &self.p
    }

    /// Mutable covariance, for models that reset or inflate states.
    pub(crate) fn covariance_mut(&mut self) -> &mut Mat {
        &mut self.p
    }

    /// Standard deviation of state `i`.
    pub(crate) fn sd(&self, i: usize) -> f64 {
        self.p.get(i, i).max(0.0).sqrt()
    }

    /// Seconds accumulated since the last propagation.
    pub(crate) fn pending_dt(&self) -> f64 {
        self.window.dt
    }

    /// Adds one mechanization step to the propagation window.
    #[inline]
    pub(crate) fn accumulate(&mut self, step: &StepInfo) {
        self.window.add(step);
        if self.layout.misalign.is_some() {
            self.window.add_misalign(step);
        }
    }

    /// Propagates P over the accumulated window, linearised at `nav` (the
    /// state at the end of the window). A no-op for an empty window.
    ///
    /// F has the block structure [[F_nn, F_nb], [0, diag]]: the 9
    /// navigation errors couple to everything, every later state (IMU
    /// errors, extras) has diagonal dynamics. The products below use it:
    /// about 6k multiply-adds for 21 states instead of 2·21³.
    pub(crate) fn propagate(&mut self, nav: &NavState) {
        let w = self.window;
        if w.dt <= 0.0 {
            return;
        }
        self.window = Window::default();
        if let Some(t) = self.track.as_mut() {
            t.close_open(&self.p);
        }
        let le = LocalEarth::new(&nav.pos, &nav.vel);
        model::fill_transition(
            &mut self.a,
            &w,
            &le,
            &nav.vel,
            self.noise.corr_time_s,
            &self.layout,
        );
        model::fill_noise(&mut self.q, &w, &self.noise, &self.layout);

        const NN: usize = 9;
        let n = self.n;
        let a = &self.a.data;
        // Φ rows of the navigation errors: I + A + A²/2, with
        // (A²)_n,: = A_nn A_n,: + A_nb diag(a_b) on the later columns.
        let phi = &mut self.phi;
        phi[..NN * n].copy_from_slice(&a[..NN * n]);
        for i in 0..NN {
            let prow = &mut phi[i * n..(i + 1) * n];
            for k in 0..NN {
                let aik = 0.5 * a[i * n + k];
                if aik == 0.0 {
                    continue;
                }
                for (pv, av) in prow.iter_mut().zip(&a[k * n..(k + 1) * n]) {
                    *pv += aik * av;
                }
            }
            for j in NN..n {
                prow[j] += 0.5 * a[i * n + j] * a[j * n + j];
            }
            prow[i] += 1.0;
        }
        // Diagonal part: φ_b = 1 + a + a²/2.
        let mut d = [0.0f64; MAX_STATES];
        for j in NN..n {
            let ajj = a[j * n + j];
            d[j] = 1.0 + ajj + 0.5 * ajj * ajj;
        }

        // M = P + Q/2
        add_half_q(&mut self.p, &self.q);
        let m = &mut self.p.data;
        // T = Φ_n M  (9 × n)
        let t = &mut self.t;
        t.iter_mut().for_each(|x| *x = 0.0);
        for i in 0..NN {
            let trow = &mut t[i * n..(i + 1) * n];
            for k in 0..n {
                let pik = phi[i * n + k];
                if pik == 0.0 {
                    continue;
                }
                for (tv, mv) in trow.iter_mut().zip(&m[k * n..(k + 1) * n]) {
                    *tv += pik * mv;
                }
            }
        }
        // bias-bias: d_i M_ij d_j
        for i in NN..n {
            for j in NN..n {
                m[i * n + j] *= d[i] * d[j];
            }
        }
        // nav-bias: T_:,b diag(d)
        for i in 0..NN {
            for j in NN..n {
                let v = t[i * n + j] * d[j];
                m[i * n + j] = v;
                m[j * n + i] = v;
            }
        }
        // nav-nav: T Φ_nᵀ
        for i in 0..NN {
            for j in i..NN {
                let v: f64 = t[i * n..(i + 1) * n]
                    .iter()
                    .zip(&phi[j * n..(j + 1) * n])
                    .map(|(x, y)| x * y)
                    .sum();
                m[i * n + j] = v;
                m[j * n + i] = v;
            }
        }
        add_half_q(&mut self.p, &self.q);
        // Every block above was written symmetrically: P stays exactly symmetric.
        self.phi_diag[NN..n].copy_from_slice(&d[NN..n]);
        if let Some(track) = self.track.as_mut() {
            accumulate_transition(&mut track.phi_acc, phi, &self.phi_diag, NN);
            if track
                .last_node
                .is_some_and(|l| nav.time.seconds_since(l) >= track.interval_s)
            {
                track.emit(nav.time, self.p.clone(), &self.p, vec![0.0; n]);
            }
        }
    }

    /// H's sparsity, HP (m × n, through that sparsity) and the innovation
    /// covariance S = H P Hᵀ + R of `obs`.
    fn innovation_parts(&self, obs: &Observation) -> (RowPattern, Mat, Mat) {
        let m = obs.dim();
        let mut hpat = RowPattern::default();
        RowPattern::scan(&obs.h, &mut hpat);
        // PHᵀ = (HP)ᵀ since P is symmetric.
        let mut hp = Mat::zeros(0, 0);
        dense::sparse_mul(&obs.h, &hpat, &self.p, &mut hp);
        let mut s = obs.r.clone();
        for a in 0..m {
            for b in 0..m {
                let mut v = 0.0;
                for &k in hpat.row(b) {
                    v += hp.get(a, k) * obs.h.get(b, k);
                }
                s.add_at(a, b, v);
            }
        }
        s.symmetrize();
        (hpat, hp, s)
    }

    /// The innovation covariance S = H P Hᵀ + R of `obs` at the current P.
    pub(crate) fn innovation_covariance(&self, obs: &Observation) -> Mat {
        self.innovation_parts(obs).2
    }

    /// Multiplies the covariance by `factor` ≥ 1 (a fading-memory step,
    /// Fagin 1964; Xia et al. 1994): the filter admits that its model left
    /// errors out. The axis misalignments are held: they are constants of
    /// the IMU whose σ is the datasheet's, not errors that grew, and
    /// inflated they take up whatever the fixes disagree with. Fixes whose
    /// σ were stated 5× too small inflated P ×17, ×32, ×23 in 100 s, which
    /// opened them to tens of degrees, past the small-angle model, and the
    /// solution reached 10⁴ m/s; capped at 1° instead, they left the
    /// solution 8× worse than the 21 states' on another drive
    /// (docs/integrity.md). P
    /// becomes D P D with D = diag(√factor, …, 1 on the misalignments): a
    /// congruence, so P stays positive semi-definite; their
    /// cross-covariances scale by √factor.
    pub(crate) fn inflate(&mut self, factor: f64) {
        if !(factor.is_finite() && factor > 1.0) {
            return;
        }
        let held = self.layout.misalign.map_or(0..0, |first| first..first + 12);
        let root = factor.sqrt();
        for i in 0..self.n {
            for j in 0..self.n {
                let m = match (held.contains(&i), held.contains(&j)) {
                    (false, false) => factor,
                    (true, true) => 1.0,
                    _ => root,
                };
                let x = self.p.get(i, j) * m;
                self.p.set(i, j, x);
            }
        }
    }

    /// Kalman update with `obs` (Joseph form). With `gate = Some(t)` the
    /// measurement is rejected when its NIS exceeds `t`. Errors when the
    /// innovation covariance or the updated P is not positive definite.
    #[cfg(test)]
    pub(crate) fn update(
        &mut self,
        obs: &Observation,
        gate: Option<f64>,
        time: GpsTime,
    ) -> Result<UpdateOutcome, Error> {
        self.update_with_frozen(obs, gate, &[], time)
    }

    /// As [`Self::update`], but the states in `frozen` are not updated (their
    /// gain rows are zero, a Schmidt "consider" update); the Joseph form
    /// keeps P exact for this suboptimal gain, so those states keep their
    /// estimate and an honest covariance.
    pub(crate) fn update_with_frozen(
        &mut self,
        obs: &Observation,
        gate: Option<f64>,
        frozen: &[usize],
        time: GpsTime,
    ) -> Result<UpdateOutcome, Error> {
        let n = self.n;
        let m = obs.dim();
        debug_assert_eq!(obs.h.cols, n);
        let (hpat, hp, s) = self.innovation_parts(obs);
        let l = dense::cholesky(&s).ok_or_else(|| Error::Covariance {
            time,
            msg: self.explain_innovation(obs, &s),
        })?;
        let mut s_inv_z = obs.z.clone();
        dense::cholesky_solve(&l, &mut s_inv_z);
        let nis: f64 = obs.z.iter().zip(&s_inv_z).map(|(a, b)| a * b).sum();
        if !nis.is_finite() {
            return Err(Error::Covariance {
                time,
                msg: format!("{} innovation is not finite", obs.kind),
            });
        }
        if let Some(threshold) = gate
            && nis > threshold
        {
            return Ok(UpdateOutcome {
                nis,
                accepted: false,
                dx: vec![0.0; n],
            });
        }
        // K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ
        let s_inv = dense::cholesky_inverse(&l);
        let mut kt = Mat::zeros(0, 0); // m × n
        dense::mul(&s_inv, &hp, &mut kt);
        let mut k = Mat::zeros(0, 0); // n × m
        kt.transpose_into(&mut k);
        for &i in frozen {
            k.row_mut(i).iter_mut().for_each(|x| *x = 0.0);
        }
        let mut dx = vec![0.0; n];
        for (i, d) in dx.iter_mut().enumerate() {
            *d = k.row(i).iter().zip(&obs.z).map(|(a, b)| a * b).sum();
        }
        if let Some(t) = self.track.as_mut() {
            for (a, b) in t.open_at(time, &self.p).iter_mut().zip(&dx) {
                *a += b;
            }
        }

        // Joseph form: P = (I − KH) P (I − KH)ᵀ + K R Kᵀ.
        // M = P − K (HP)
        let mut khp = Mat::zeros(0, 0);
        dense::mul(&k, &hp, &mut khp);
        let mut mm = self.p.clone();
        for (x, y) in mm.data.iter_mut().zip(&khp.data) {
            *x -= y;
        }
        // P' = M − (M Hᵀ) Kᵀ + K R Kᵀ
        let mut mht = Mat::zeros(n, m);
        for i in 0..n {
            for a in 0..m {
                let mut v = 0.0;
                for &c in hpat.row(a) {
                    v += mm.get(i, c) * obs.h.get(a, c);
                }
                mht.set(i, a, v);
            }
        }
        let mut kr = Mat::zeros(0, 0);
        dense::mul(&k, &obs.r, &mut kr);
        // combined: (K R − M Hᵀ) Kᵀ
        for (x, y) in kr.data.iter_mut().zip(&mht.data) {
            *x -= y;
        }
        let mut corr = Mat::zeros(0, 0);
        dense::mul_transpose(&kr, &k, &mut corr);
        for (x, y) in mm.data.iter_mut().zip(&corr.data) {
            *x += y;
        }
        mm.symmetrize();
        self.p = mm;
        self.check_covariance(time)?;
        Ok(UpdateOutcome {
            nis,
            accepted: true,
            dx,
        })
    }

    /// Why the variances are unusable, if they are: one not finite or
    /// negative, or a navigation state's (position, velocity, attitude)
    /// not positive. A cheap check (the diagonal) for every epoch.
    pub(crate) fn variance_problem(&self) -> Option<String> {
        (0..self.n).find_map(|i| {
            let d = self.p.get(i, i);
            let ok = d.is_finite() && (d > 0.0 || (i >= 9 && d == 0.0));
            (!ok).then(|| format!("variance of state {i} is {d:e}"))
        })
    }

    /// Errors unless P is finite, symmetric by construction and positive
    /// definite (Cholesky succeeds after the tiniest relative jitter).
    pub(crate) fn check_covariance(&self, time: GpsTime) -> Result<(), Error> {
        let n = self.n;
        for i in 0..n {
            let d = self.p.get(i, i);
            if !d.is_finite() || d < 0.0 {
                return Err(Error::Covariance {
                    time,
                    msg: format!("variance of {} is {d}", self.layout.state_name(i)),
                });
            }
        }
        // Scale to a correlation matrix so the test is independent of units.
        let mut c = self.p.clone();
        let sd: Vec<f64> = (0..n)
            .map(|i| self.p.get(i, i).sqrt().max(1e-300))
            .collect();
        for i in 0..n {
            for j in 0..n {
                c.data[i * n + j] /= sd[i] * sd[j];
            }
            c.data[i * n + i] += 1e-12;
        }
        if dense::cholesky(&c).is_none() {
            // The first leading block that fails names the state that the
            // ones before it (numerically) determine.
            let k = (1..=n)
                .find(|&k| {
                    let mut b = Mat::zeros(k, k);
                    for i in 0..k {
                        for j in 0..k {
                            b.data[i * k + j] = c.data[i * n + j];
                        }
                    }
                    dense::cholesky(&b).is_none()
                })
                .unwrap_or(n);
            return Err(Error::Covariance {
                time,
                msg: format!(
                    "covariance P is not positive definite at {}: it is (numerically) \
                     determined by the states before it (σ {:.3e}). Likely cause: a σ many \
                     orders of magnitude below the others (initial σ, measurement σ or \
                     noise in the configuration) or two states the data cannot tell apart",
                    self.layout.state_name(k - 1),
                    sd[k - 1]
                ),
            });
        }
        Ok(())
    }

    /// Why S = H P Hᵀ + R of `obs` is not positive definite: the first
    /// axis whose R or H P Hᵀ is not a finite positive number, and the
    /// likely cause.
    fn explain_innovation(&self, obs: &Observation, s: &Mat) -> String {
        let head = format!(
            "{} innovation covariance S = HPHᵀ + R is not positive definite",
            obs.kind
        );
        for a in 0..obs.dim() {
            let r = obs.r.get(a, a);
            let hph = s.get(a, a) - r;
            if !(r.is_finite() && r > 0.0) {
                return format!(
                    "{head}: axis {a} has measurement variance R = {r:e}; the measurement's σ \
                     must be a positive finite number (check the σ given for {})",
                    obs.kind
                );
            }
            if !hph.is_finite() {
                let worst = (0..self.n)
                    .filter(|&i| obs.h.get(a, i) != 0.0)
                    .find(|&i| !self.p.get(i, i).is_finite() || self.p.get(i, i) > 1e150);
                let state = worst.map_or_else(
                    || "the states it observes".to_string(),
                    |i| self.layout.state_name(i),
                );
                return format!(
                    "{head}: axis {a} has HPHᵀ = {hph:e}, R = {r:e}: the filter's covariance of \
                     {state} overflowed (an initial σ far too large, or the filter diverged before)"
                );
            }
        }
        format!(
            "{head}: every axis has a finite positive variance but S is singular (axes \
             measuring the same thing with σ = 0 correlation?); R diagonal {:?}",
            (0..obs.dim()).map(|a| obs.r.get(a, a)).collect::<Vec<_>>()
        )
    }
}

/// acc ← Φ acc for Φ whose first `nn` rows are dense (`phi_rows`, row-major,
/// n columns) and whose remaining rows are diagonal (`diag`).
fn accumulate_transition(acc: &mut Mat, phi_rows: &[f64], diag: &[f64], nn: usize) {
    let n = acc.rows;
    let mut top = vec![0.0; nn * n];
    for i in 0..nn {
        let out = &mut top[i * n..(i + 1) * n];
        for k in 0..n {
            let f = phi_rows[i * n + k];
            if f == 0.0 {
                continue;
            }
            for (o, a) in out.iter_mut().zip(acc.row(k)) {
                *o += f * a;
            }
        }
    }
    for j in nn..n {
        let d = diag[j];
        acc.row_mut(j).iter_mut().for_each(|x| *x *= d);
    }
    acc.data[..nn * n].copy_from_slice(&top);
}

/// P += Q/2 over Q's block-diagonal support (velocity and attitude 3×3
/// blocks, diagonal elsewhere).
fn add_half_q(p: &mut Mat, q: &Mat) {
    let n = p.rows;
    for start in [idx::VEL, idx::ATT] {
        for i in start..start + 3 {
            for j in start..start + 3 {
                p.data[i * n + j] += 0.5 * q.data[i * n + j];
            }
        }
    }
    for i in idx::BG..n {
        p.data[i * n + i] += 0.5 * q.data[i * n + i];
    }
}

/// Applies the estimated error state to the navigation state and the IMU
/// error estimates (closed-loop feedback; KF-GINS doc §3.8 "Error State
/// Feedback", with this module's sign convention δx = x̂ − x).
pub(crate) fn feedback(dx: &[f64], layout: &StateLayout, nav: &mut NavState, imu: &mut ImuErrors) {
    let v3 = |i: usize| Vector3::new(dx[i], dx[i + 1], dx[i + 2]);
    let le = LocalEarth::new(&nav.pos, &nav.vel);
    let dp = le.ned_to_geodetic_delta(&v3(idx::POS));
    nav.pos.lat_rad -= dp.x;
    nav.pos.lon_rad -= dp.y;
    nav.pos.h_m -= dp.z;
    nav.vel -= v3(idx::VEL);
    // Ĉ = (I − φ×) C  ⇒  C = exp(φ×) Ĉ
    nav.q_nb = crate::attitude::rotvec_to_quat(&v3(idx::ATT)) * nav.q_nb;
    nav.q_nb.renormalize();
    imu.gyro_bias -= v3(idx::BG);
    imu.accel_bias -= v3(idx::BA);
    imu.gyro_scale -= v3(idx::SG);
    imu.accel_scale -= v3(idx::SA);
    if let Some(m) = layout.misalign {
        for k in 0..6 {
            imu.gyro_misalign[k] -= dx[m + k];
            imu.accel_misalign[k] -= dx[m + 6 + k];
        }
    }
}
