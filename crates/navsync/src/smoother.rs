//! Fixed-interval smoothing of the closed-loop error-state filter: the
//! Rauch–Tung–Striebel (RTS) backward pass (Rauch, Tung & Striebel,
//! "Maximum likelihood estimates of linear dynamic systems", AIAA J. 3(8),
//! 1965; Groves, *Principles of GNSS, Inertial, and Multisensor Integrated
//! Navigation Systems*, 2nd ed., §3.4.2).
//!
//! # The backward pass with closed-loop feedback
//!
//! The forward filter ([`crate::fusion`]) keeps a nominal state x̂ and an
//! error state δx = x̂ − x whose mean it feeds back at once: after the
//! corrections at node k the nominal is x̂ₖ⁺ = x̂ₖ⁻ ⊖ dxₖ (for vectors
//! x̂ₖ⁺ = x̂ₖ⁻ − dxₖ, for attitude the rotation of `crate::filter::feedback`),
//! and the filter's error-state mean is zero again, with covariance Pₖ⁺.
//! Between nodes the nominal is mechanized from x̂ₖ⁺, so the error of the
//! nominal obeys δxₖ₊₁⁻ = Φₖ δxₖ⁺ + wₖ with predicted mean 0 and
//! covariance Pₖ₊₁⁻. Both filter means being zero, the RTS recursion for
//! the smoothed error eₖ of the *corrected* nominal x̂ₖ⁺ is
//!
//! ```text
//!   Aₖ    = Pₖ⁺ Φₖᵀ (Pₖ₊₁⁻)⁻¹
//!   eₖ₊₁⁻ = eₖ₊₁ + dxₖ₊₁        (the same estimate, relative to x̂ₖ₊₁⁻)
//!   eₖ    = Aₖ eₖ₊₁⁻
//!   Pₖˢ   = Pₖ⁺ + Aₖ (Pₖ₊₁ˢ − Pₖ₊₁⁻) Aₖᵀ
//! ```
//!
//! starting from e_N = 0, P_Nˢ = P_N⁺ at the last node. The second line is
//! the only change the feedback brings: the smoothed estimate at k+1 is
//! expressed against the nominal the forward filter *predicted* (x̂ₖ₊₁⁻,
//! which is what Φₖ maps x̂ₖ⁺'s error onto), i.e. the feedback dxₖ₊₁ is
//! added back. (Shin, *Estimation Techniques for Low-Cost Inertial
//! Navigation*, PhD thesis, University of Calgary, 2005, treats the RTS
//! smoother of a closed-loop INS/GPS filter the same way.) The smoothed
//! state is x̂ₖ⁺ ⊖ eₖ. The test `closed_loop_rts_equals_batch_least_squares`
//! checks this recursion against the batch solution to 1e-9.
//!
//! # Memory and time
//!
//! Nodes are stored only at correction epochs and at least every
//! `node_interval_s` between them (the transition Φ accumulated over the
//! filter's propagation steps), in a temporary file, not in memory: 21
//! states take 7 kB a node. The backward pass reads them in reverse and
//! writes the smoothed corrections (another file); the forward IMU-rate
//! solution is kept in a third one (88 B an epoch). The final pass reads
//! the forward solution and the corrections forward and applies, at each
//! IMU epoch, the correction interpolated linearly in time between the
//! nodes around it (eₖ after node k, eₖ₊₁⁻ before node k+1). Between two
//! nodes ≤ 1 s apart the error grows by a second-order term of a few mm/s²
//! · Δt²/8, so the interpolation costs < 1 mm.
#![warn(missing_docs)]

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::error::Error;
use crate::filter::dense::{self, Mat};
use crate::filter::{SmootherNode, StateLayout, feedback};
use crate::ins::{ImuErrors, NavState};
use crate::time::GpsTime;

/// A temporary file of fixed-size records of `f64`, removed when dropped.
/// Written once in order, then read in any order through a block cache.
pub(crate) struct RecordFile {
    path: PathBuf,
    record_len: usize,
    writer: Option<BufWriter<File>>,
    reader: Option<File>,
    len: usize,
    /// Cached block: first record index and its data.
    block_start: usize,
    block: Vec<f64>,
}

/// Records read or written at a time.
const BLOCK_BYTES: usize = 1 << 20;

impl RecordFile {
    /// A new, empty file of records of `record_len` values in `dir`.
    pub(crate) fn create(dir: &Path, tag: &str, record_len: usize) -> Result<Self, Error> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        // `.navsync-<tag>.<pid>-<k>.tmp`, registered with the output
        // registry (a signal handler removes it; a later run into the
        // folder removes it once this process is dead).
        let path = crate::io::output::temp_path(&dir.join(tag));
        let file = crate::io::output::create_temp(&path, true)?;
        Ok(RecordFile {
            path,
            record_len,
            writer: Some(BufWriter::with_capacity(BLOCK_BYTES, file)),
            reader: None,
            len: 0,
            block_start: 0,
            block: Vec::new(),
        })
    }

    /// Number of records.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Bytes on disk.
    pub(crate) fn bytes(&self) -> u64 {
        (self.len * self.record_len * 8) as u64
    }

    /// Appends one record (`values.len()` must be the record length).
    pub(crate) fn push(&mut self, values: &[f64]) -> Result<(), Error> {
        debug_assert_eq!(values.len(), self.record_len);
        let w = self
            .writer
            .as_mut()
            .ok_or_else(|| Error::Invalid("record file already read".into()))?;
        for v in values {
            w.write_all(&v.to_le_bytes())
                .map_err(|e| Error::io(&self.path, e))?;
        }
        self.len += 1;
        Ok(())
    }

    /// Keeps the first `k` records (while writing): a rollback's re-run
    /// records the epochs after them again.
    pub(crate) fn truncate(&mut self, k: usize) -> Result<(), Error> {
        if k >= self.len {
            return Ok(());
        }
        let w = self
            .writer
            .as_mut()
            .ok_or_else(|| Error::Invalid("record file already read".into()))?;
        let bytes = (k * self.record_len * 8) as u64;
        w.flush().map_err(|e| Error::io(&self.path, e))?;
        w.get_mut()
            .set_len(bytes)
            .map_err(|e| Error::io(&self.path, e))?;
        w.seek(SeekFrom::Start(bytes))
            .map_err(|e| Error::io(&self.path, e))?;
        self.len = k;
        Ok(())
    }

    /// Record `k` (the file is closed for writing on the first read).
    pub(crate) fn get(&mut self, k: usize) -> Result<&[f64], Error> {
        if k >= self.len {
            return Err(Error::Invalid(format!(
                "record {k} of {} requested from {}",
                self.len,
                self.path.display()
            )));
        }
        if let Some(w) = self.writer.take() {
            let f = w
                .into_inner()
                .map_err(|e| Error::io(&self.path, e.into_error()))?;
            self.reader = Some(f);
            self.block.clear();
        }
        let per_block = (BLOCK_BYTES / (8 * self.record_len)).max(1);
        let cached = self.block.len() / self.record_len;
        if k < self.block_start || k >= self.block_start + cached {
            // Centre reads so that both directions stay in the block.
            let start = (k / per_block) * per_block;
            let count = per_block.min(self.len - start);
            let f = self
                .reader
                .as_mut()
                .ok_or_else(|| Error::Invalid("record file is not readable".into()))?;
            f.seek(SeekFrom::Start((start * self.record_len * 8) as u64))
                .map_err(|e| Error::io(&self.path, e))?;
            let mut bytes = vec![0u8; count * self.record_len * 8];
            f.read_exact(&mut bytes)
                .map_err(|e| Error::io(&self.path, e))?;
            self.block = bytes
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect();
            self.block_start = start;
        }
        let i = (k - self.block_start) * self.record_len;
        Ok(&self.block[i..i + self.record_len])
    }
}

impl Drop for RecordFile {
    fn drop(&mut self) {
        self.writer = None;
        self.reader = None;
        crate::io::output::remove_temp(&self.path);
    }
}

fn time_to_f64(t: GpsTime) -> f64 {
    f64::from_bits(t.ns() as u64)
}

fn time_from_f64(v: f64) -> GpsTime {
    GpsTime::from_ns(v.to_bits() as i64)
}

/// The forward filter's nominal values of the states that are not
/// navigation states, after a node's corrections.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct NodeNominal {
    pub imu: ImuErrors,
    /// Time offset τ̂ (s) and odometer scale, when they are states.
    pub time_offset_s: f64,
    pub(crate) odometer_scale: f64,
    /// The forward filter held the yaw (heading unknown, σ beyond 90°: a
    /// vehicle that had not moved yet): a consider state there, never
    /// corrected, so the backward pass does not correct it either.
    pub(crate) yaw_held: bool,
}

const NOMINAL_LEN: usize = 27;

impl NodeNominal {
    fn write(&self, out: &mut Vec<f64>) {
        let i = &self.imu;
        out.extend(i.gyro_bias.iter());
        out.extend(i.accel_bias.iter());
        out.extend(i.gyro_scale.iter());
        out.extend(i.accel_scale.iter());
        out.extend(i.gyro_misalign);
        out.extend(i.accel_misalign);
        out.push(self.time_offset_s);
        out.push(self.odometer_scale);
        out.push(if self.yaw_held { 1.0 } else { 0.0 });
    }

    fn read(v: &[f64]) -> Self {
        let v3 = |k: usize| nalgebra::Vector3::new(v[k], v[k + 1], v[k + 2]);
        let mut gm = [0.0; 6];
        gm.copy_from_slice(&v[12..18]);
        let mut am = [0.0; 6];
        am.copy_from_slice(&v[18..24]);
        NodeNominal {
            imu: ImuErrors {
                gyro_bias: v3(0),
                accel_bias: v3(3),
                gyro_scale: v3(6),
                accel_scale: v3(9),
                gyro_misalign: gm,
                accel_misalign: am,
            },
            time_offset_s: v[24],
            odometer_scale: v[25],
            yaw_held: v[26] != 0.0,
        }
    }
}

/// Packs the upper triangle of a symmetric matrix.
fn push_upper(m: &Mat, out: &mut Vec<f64>) {
    for i in 0..m.rows {
        out.extend_from_slice(&m.row(i)[i..]);
    }
}

fn read_upper(v: &[f64], n: usize) -> Mat {
    let mut m = Mat::zeros(n, n);
    let mut k = 0;
    for i in 0..n {
        for j in i..n {
            m.set(i, j, v[k]);
            m.set(j, i, v[k]);
            k += 1;
        }
    }
    m
}

/// The forward run's nodes (on disk) and its IMU-rate solution (on disk).
pub(crate) struct Recorder {
    n: usize,
    nodes: RecordFile,
    tape: RecordFile,
    scratch: Vec<f64>,
    dir: PathBuf,
}

const TAPE_LEN: usize = 11;

impl Recorder {
    /// A recorder for `n` error states with its files in `dir`.
    pub(crate) fn create(dir: &Path, n: usize) -> Result<Self, Error> {
        let tri = n * (n + 1) / 2;
        Ok(Recorder {
            n,
            nodes: RecordFile::create(dir, "nodes", 1 + n * n + 2 * tri + n + NOMINAL_LEN)?,
            tape: RecordFile::create(dir, "forward", TAPE_LEN)?,
            scratch: Vec::new(),
            dir: dir.to_path_buf(),
        })
    }

    /// Stores one node with the nominal state after its corrections.
    pub(crate) fn push_node(
        &mut self,
        node: &SmootherNode,
        nominal: &NodeNominal,
    ) -> Result<(), Error> {
        let v = &mut self.scratch;
        v.clear();
        v.push(time_to_f64(node.time));
        v.extend_from_slice(&node.phi_in.data);
        push_upper(&node.p_minus, v);
        push_upper(&node.p_plus, v);
        v.extend_from_slice(&node.dx);
        nominal.write(v);
        self.nodes.push(v)
    }

    /// Stores the forward solution at one output epoch.
    pub(crate) fn push_nav(&mut self, nav: &NavState) -> Result<(), Error> {
        let q = nav.q_nb.quaternion();
        self.tape.push(&[
            time_to_f64(nav.time),
            nav.pos.lat_rad,
            nav.pos.lon_rad,
            nav.pos.h_m,
            nav.vel.x,
            nav.vel.y,
            nav.vel.z,
            q.w,
            q.i,
            q.j,
            q.k,
        ])
    }

    /// The numbers of nodes and of solutions recorded.
    pub(crate) fn lengths(&self) -> (usize, usize) {
        (self.nodes.len(), self.tape.len())
    }

    /// Keeps the first `nodes` nodes and `tape` solutions (a rollback).
    pub(crate) fn truncate(&mut self, nodes: usize, tape: usize) -> Result<(), Error> {
        self.nodes.truncate(nodes)?;
        self.tape.truncate(tape)
    }

    pub(crate) fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes of the temporary files.
    pub(crate) fn bytes(&self) -> u64 {
        self.nodes.bytes() + self.tape.bytes()
    }

    fn read_node(&mut self, k: usize) -> Result<(SmootherNode, NodeNominal), Error> {
        let n = self.n;
        let tri = n * (n + 1) / 2;
        let v = self.nodes.get(k)?;
        let mut o = 1;
        let mut phi_in = Mat::zeros(n, n);
        phi_in.data.copy_from_slice(&v[o..o + n * n]);
        o += n * n;
        let p_minus = read_upper(&v[o..o + tri], n);
        o += tri;
        let p_plus = read_upper(&v[o..o + tri], n);
        o += tri;
        let dx = v[o..o + n].to_vec();
        o += n;
        let nominal = NodeNominal::read(&v[o..o + NOMINAL_LEN]);
        Ok((
            SmootherNode {
                time: time_from_f64(v[0]),
                phi_in,
                p_minus,
                p_plus,
                dx,
            },
            nominal,
        ))
    }

    /// The backward pass over every node. The nodes' file is dropped.
    pub(crate) fn smooth(mut self, layout: StateLayout) -> Result<Smoothed, Error> {
        let n = self.n;
        let count = self.nodes.len();
        if count == 0 {
            return Err(Error::Invalid("the smoother recorded no node".into()));
        }
        // Result record: time, e⁺ (n), e⁻ (n), σ (n), position covariance
        // (9), nominal.
        let rec_len = 1 + 3 * n + 9 + NOMINAL_LEN;
        let mut out = RecordFile::create(&self.dir, "smoothed", rec_len)?;
        let (last, last_nom) = self.read_node(count - 1)?;
        let mut next = BackwardStep {
            e: vec![0.0; n],
            p: last.p_plus.clone(),
        };
        let mut next_node = last;
        let mut next_held = last_nom.yaw_held;
        write_result(&mut out, &next_node, &next, &last_nom)?;
        let mut failures = 0usize;
        let yaw = crate::filter::idx::ATT + 2;
        for k in (0..count - 1).rev() {
            let (node, nominal) = self.read_node(k)?;
            let held = Held {
                this: nominal.yaw_held.then_some(yaw),
                next: next_held.then_some(yaw),
            };
            let (mut step, ok) = rts_step(&node.p_plus, &next_node, &next, held);
            failures += usize::from(!ok);
            // NaN guard: a step that is not finite restarts the recursion
            // from the forward estimate here (counted as a failure), so
            // nothing non-finite is carried back.
            if !step_is_finite(&step) {
                failures += usize::from(ok);
                step = BackwardStep {
                    e: vec![0.0; n],
                    p: node.p_plus.clone(),
                };
            }
            write_result(&mut out, &node, &step, &nominal)?;
            next = step;
            next_node = node;
            next_held = nominal.yaw_held;
        }
        Ok(Smoothed {
            n,
            layout,
            results: out,
            tape: self.tape,
            count,
            failures,
            yaw_turn: None,
        })
    }
}

/// True when the smoothed error and its variances are finite.
fn step_is_finite(s: &BackwardStep) -> bool {
    s.e.iter().all(|v| v.is_finite()) && (0..s.e.len()).all(|i| s.p.get(i, i).is_finite())
}

/// The smoothed error of a node's corrected nominal and its covariance.
#[derive(Clone, Debug)]
pub(crate) struct BackwardStep {
    pub e: Vec<f64>,
    pub p: Mat,
}

/// A state the forward filter held as a consider state (Schmidt, "Application
/// of state-space methods to navigation problems", 1966: its covariance
/// carried, its estimate never corrected) at node k (`this`) and at node
/// k+1 (`next`). The forward filter held the yaw while the heading was
/// unknown because a small-angle error model linearised at a heading that
/// may be 180° off says nothing true about it; the backward pass must not
/// correct it either: its smoothed error is kept at zero (the forward
/// nominal), and it passes no correction on to the other states. Without
/// this, a hovering drone's smoothed track ran hundreds of metres off
/// through the yaw–velocity cross-covariances.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Held {
    pub this: Option<usize>,
    pub next: Option<usize>,
}

/// One RTS step: node k's posterior covariance `p_plus`, node k+1 and its
/// smoothed estimate, the states held at either node. Returns node k's
/// smoothed estimate, and false when P⁻ₖ₊₁ had to be regularised.
pub(crate) fn rts_step(
    p_plus: &Mat,
    next: &SmootherNode,
    next_s: &BackwardStep,
    held: Held,
) -> (BackwardStep, bool) {
    let n = p_plus.rows;
    // M = Φ P⁺ ; Aᵀ = (P⁻)⁻¹ M, column by column.
    let mut m = Mat::zeros(0, 0);
    dense::mul(&next.phi_in, p_plus, &mut m);
    // A held state is marginalised out of the gain: M's and P⁻'s rows and
    // columns of it are dropped (kept as an identity so the dimensions
    // stay), so Aₛₛ = [P⁺Φᵀ]ₛₛ (P⁻ₛₛ)⁻¹ conditions the estimated states
    // of node k on those of node k+1 alone, and A's held row and column
    // are zero.
    let decoupled;
    let p_minus = match held.this.into_iter().chain(held.next).next() {
        Some(h) => {
            let mut p = next.p_minus.clone();
            for i in 0..n {
                p.set(h, i, 0.0);
                p.set(i, h, 0.0);
                m.set(h, i, 0.0);
                m.set(i, h, 0.0);
            }
            p.set(h, h, 1.0);
            decoupled = p;
            &decoupled
        }
        None => &next.p_minus,
    };
    let (l, ok) = spd_factor(p_minus);
    let mut a = Mat::zeros(n, n);
    let mut col = vec![0.0; n];
    for j in 0..n {
        for (i, c) in col.iter_mut().enumerate() {
            *c = m.get(i, j);
        }
        dense::cholesky_solve(&l, &mut col);
        // column j of Aᵀ is row j of A
        a.row_mut(j).copy_from_slice(&col);
    }
    // e⁻ₖ₊₁ = eₖ₊₁ + dxₖ₊₁ ; eₖ = A e⁻ₖ₊₁
    let mut e_pre: Vec<f64> = next_s.e.iter().zip(&next.dx).map(|(a, b)| a + b).collect();
    if let Some(i) = held.next {
        e_pre[i] = 0.0;
    }
    let mut e: Vec<f64> = (0..n)
        .map(|i| a.row(i).iter().zip(&e_pre).map(|(x, y)| x * y).sum())
        .collect();
    if let Some(i) = held.this {
        e[i] = 0.0;
    }
    // Pˢ = P⁺ + A (Pˢₖ₊₁ − P⁻ₖ₊₁) Aᵀ
    let mut d = next_s.p.clone();
    for (x, y) in d.data.iter_mut().zip(&next.p_minus.data) {
        *x -= y;
    }
    let mut ad = Mat::zeros(0, 0);
    dense::mul(&a, &d, &mut ad);
    let mut adat = Mat::zeros(0, 0);
    dense::mul_transpose(&ad, &a, &mut adat);
    let mut p = p_plus.clone();
    for (x, y) in p.data.iter_mut().zip(&adat.data) {
        *x += y;
    }
    p.symmetrize();
    (BackwardStep { e, p }, ok)
}

/// Cholesky factor of a covariance; when it is not numerically positive
/// definite, of the matrix with a relative jitter of 1e-12 on the diagonal
/// (flagged by `false`).
fn spd_factor(p: &Mat) -> (Mat, bool) {
    if let Some(l) = dense::cholesky(p) {
        return (l, true);
    }
    let mut q = p.clone();
    let n = q.rows;
    for i in 0..n {
        let d = q.get(i, i).abs().max(1e-300);
        q.add_at(i, i, d * 1e-12 + 1e-300);
    }
    match dense::cholesky(&q) {
        Some(l) => (l, false),
        None => {
            let mut d = Mat::zeros(n, n);
            for i in 0..n {
                d.set(i, i, p.get(i, i).abs().max(1e-300).sqrt());
            }
            (d, false)
        }
    }
}

fn write_result(
    out: &mut RecordFile,
    node: &SmootherNode,
    s: &BackwardStep,
    nominal: &NodeNominal,
) -> Result<(), Error> {
    let n = s.e.len();
    let mut v = Vec::with_capacity(1 + 3 * n + 9 + NOMINAL_LEN);
    v.push(time_to_f64(node.time));
    v.extend_from_slice(&s.e);
    v.extend(s.e.iter().zip(&node.dx).map(|(a, b)| a + b));
    v.extend((0..n).map(|i| s.p.get(i, i).max(0.0).sqrt()));
    for i in 0..3 {
        for j in 0..3 {
            v.push(s.p.get(i, j));
        }
    }
    nominal.write(&mut v);
    out.push(&v)
}

/// One smoothed node, read back.
#[derive(Clone, Debug)]
struct ResultNode {
    time: GpsTime,
    e_post: Vec<f64>,
    e_pre: Vec<f64>,
    sd: Vec<f64>,
    p_pos: [f64; 9],
    nominal: NodeNominal,
}

/// The smoothed solution at one epoch.
#[derive(Clone, Debug)]
pub(crate) struct SmoothedEpoch {
    pub nav: NavState,
    pub imu: ImuErrors,
    /// σ of every state (SI), interpolated between nodes.
    pub sd: Vec<f64>,
    /// Position-error covariance (m², NED).
    pub(crate) p_pos: nalgebra::Matrix3<f64>,
    pub time_offset_s: f64,
}

/// The backward pass's result: smoothed corrections at every node, and the
/// forward solution they apply to.
pub struct Smoothed {
    n: usize,
    layout: StateLayout,
    /// Written from the last node to the first.
    results: RecordFile,
    tape: RecordFile,
    count: usize,
    /// Nodes where P⁻ was regularised.
    pub(crate) failures: usize,
    /// The heading found in the run (`crate::fusion::course_heading`):
    /// epochs whose yaw was held before it are turned by its offset.
    pub(crate) yaw_turn: Option<crate::fusion::course_heading::HeadingAcquired>,
}

impl Smoothed {
    pub(crate) fn node_count(&self) -> usize {
        self.count
    }

    /// Forward epochs stored.
    pub fn epochs(&self) -> usize {
        self.tape.len()
    }

    fn node(&mut self, k: usize) -> Result<ResultNode, Error> {
        let n = self.n;
        let v = self.results.get(self.count - 1 - k)?;
        let mut p_pos = [0.0; 9];
        p_pos.copy_from_slice(&v[1 + 3 * n..1 + 3 * n + 9]);
        Ok(ResultNode {
            time: time_from_f64(v[0]),
            e_post: v[1..1 + n].to_vec(),
            e_pre: v[1 + n..1 + 2 * n].to_vec(),
            sd: v[1 + 2 * n..1 + 3 * n].to_vec(),
            p_pos,
            nominal: NodeNominal::read(&v[1 + 3 * n + 9..]),
        })
    }

    /// Calls `f` with the smoothed solution at every forward epoch, in
    /// time order.
    pub(crate) fn for_each(
        &mut self,
        mut f: impl FnMut(&SmoothedEpoch) -> Result<(), Error>,
    ) -> Result<(), Error> {
        let n = self.n;
        let mut k = 0usize;
        let mut a = self.node(0)?;
        let mut b = if self.count > 1 {
            Some(self.node(1)?)
        } else {
            None
        };
        let mut e = vec![0.0; n];
        let mut sd = vec![0.0; n];
        for i in 0..self.tape.len() {
            let v = self.tape.get(i)?;
            let time = time_from_f64(v[0]);
            let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                v[7], v[8], v[9], v[10],
            ));
            let mut nav = NavState {
                time,
                pos: crate::earth::Geodetic::new(v[1], v[2], v[3]),
                vel: nalgebra::Vector3::new(v[4], v[5], v[6]),
                q_nb: q,
            };
            // Advance to the segment [a, b) holding `time`.
            while let Some(nb) = &b
                && nb.time <= time
            {
                k += 1;
                if let Some(nb) = b.take() {
                    a = nb;
                }
                b = if k + 1 < self.count {
                    Some(self.node(k + 1)?)
                } else {
                    None
                };
            }
            let u = match &b {
                Some(nb) if time > a.time => {
                    (time - a.time) as f64 / (nb.time - a.time).max(1) as f64
                }
                _ => 0.0,
            };
            let (e_b, sd_b, p_b) = match &b {
                Some(nb) => (&nb.e_pre, &nb.sd, nb.p_pos),
                None => (&a.e_post, &a.sd, a.p_pos),
            };
            for j in 0..n {
                e[j] = (1.0 - u) * a.e_post[j] + u * e_b[j];
                sd[j] = (1.0 - u) * a.sd[j] + u * sd_b[j];
            }
            let mut p_pos = nalgebra::Matrix3::zeros();
            for r in 0..3 {
                for c in 0..3 {
                    p_pos[(r, c)] = (1.0 - u) * a.p_pos[r * 3 + c] + u * p_b[r * 3 + c];
                }
            }
            let mut imu = a.nominal.imu;
            feedback(&e, &self.layout, &mut nav, &mut imu);
            if let Some(h) = self.yaw_turn
                && a.nominal.yaw_held
            {
                nav.q_nb = crate::attitude::turned_in_yaw(&nav.q_nb, h.offset_rad);
                // The gyros' drift between this epoch and the acquisition
                // is left out of the σ (minutes of a MEMS gyro: a degree).
                sd[crate::filter::idx::ATT + 2] = h.sd_rad;
            }
            let extra = |name: &str| self.layout.index_of(name).map(|i| e[i]).unwrap_or(0.0);
            f(&SmoothedEpoch {
                nav,
                imu,
                sd: sd.clone(),
                p_pos,
                time_offset_s: a.nominal.time_offset_s - extra("time_offset"),
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed-loop RTS on a linear-Gaussian toy (position–velocity with a
    /// white acceleration, position fixes, feedback after every update)
    /// equals the batch least-squares solution of all measurements and
    /// the process model to 1e-9.
    #[test]
    fn closed_loop_rts_equals_batch_least_squares() {
        use crate::testutil::rng;
        let dt: f64 = 0.5;
        let q = 0.04; // acceleration PSD (m²/s³)
        let r = 0.25; // fix variance (m²)
        let steps = 40;
        let phi = [[1.0, dt], [0.0, 1.0]];
        let qd = [
            [q * dt.powi(3) / 3.0, q * dt * dt / 2.0],
            [q * dt * dt / 2.0, q * dt],
        ];
        let p0 = [[4.0, 0.0], [0.0, 1.0]];
        let x0_prior = [1.0, 0.3];
        let mut rng = rng::stream(7, "rts-toy");
        // Fixes at every other step, a gap in the middle.
        let z: Vec<Option<f64>> = (0..=steps)
            .map(|k| {
                (k % 2 == 0 && !(14..26).contains(&k)).then(|| {
                    0.2 * k as f64 + 0.3 * (k as f64 * 0.7).sin() + rng::normal(&mut rng) * 0.5
                })
            })
            .collect();

        // Forward closed-loop filter: nominal x̂, error mean 0 after feedback.
        let m2 = |a: [[f64; 2]; 2]| {
            let mut m = Mat::zeros(2, 2);
            for i in 0..2 {
                for j in 0..2 {
                    m.set(i, j, a[i][j]);
                }
            }
            m
        };
        let mut nominal = x0_prior;
        let mut p = m2(p0);
        let mut nodes = Vec::new();
        let mut nominals = Vec::new();
        for k in 0..=steps {
            let phi_in = if k == 0 {
                Mat::identity(2)
            } else {
                nominal = [nominal[0] + dt * nominal[1], nominal[1]];
                let mut fp = Mat::zeros(0, 0);
                dense::mul(&m2(phi), &p, &mut fp);
                let mut pp = Mat::zeros(0, 0);
                dense::mul_transpose(&fp, &m2(phi), &mut pp);
                for (a, b) in pp.data.iter_mut().zip(&m2(qd).data) {
                    *a += b;
                }
                p = pp;
                m2(phi)
            };
            let p_minus = p.clone();
            let mut dx = vec![0.0, 0.0];
            if let Some(zk) = z[k] {
                // innovation = predicted − measured; δx = x̂ − x
                let innov = nominal[0] - zk;
                let s = p.get(0, 0) + r;
                let kg = [p.get(0, 0) / s, p.get(1, 0) / s];
                dx = vec![kg[0] * innov, kg[1] * innov];
                let mut np = p.clone();
                for i in 0..2 {
                    for j in 0..2 {
                        np.set(i, j, p.get(i, j) - kg[i] * p.get(0, j));
                    }
                }
                np.symmetrize();
                p = np;
                nominal = [nominal[0] - dx[0], nominal[1] - dx[1]];
            }
            nodes.push(SmootherNode {
                time: GpsTime::from_ns(k as i64),
                phi_in,
                p_minus,
                p_plus: p.clone(),
                dx,
            });
            nominals.push(nominal);
        }
        // Backward pass.
        let last = nodes.len() - 1;
        let mut smoothed = vec![[0.0; 2]; nodes.len()];
        let mut next = BackwardStep {
            e: vec![0.0; 2],
            p: nodes[last].p_plus.clone(),
        };
        smoothed[last] = nominals[last];
        for k in (0..last).rev() {
            let (s, ok) = rts_step(&nodes[k].p_plus, &nodes[k + 1], &next, Held::default());
            assert!(ok);
            smoothed[k] = [nominals[k][0] - s.e[0], nominals[k][1] - s.e[1]];
            next = s;
        }

        // Batch least squares over all 2(steps+1) unknowns: prior, process
        // and measurement residuals weighted by their inverse covariances
        // (normal equations, solved by Cholesky).
        let nx = 2 * (steps + 1);
        let mut h = Mat::zeros(nx, nx);
        let mut g = vec![0.0; nx];
        let inv2 = |a: [[f64; 2]; 2]| {
            let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
            [
                [a[1][1] / det, -a[0][1] / det],
                [-a[1][0] / det, a[0][0] / det],
            ]
        };
        let w0 = inv2(p0);
        for i in 0..2 {
            for j in 0..2 {
                h.add_at(i, j, w0[i][j]);
                g[i] += w0[i][j] * x0_prior[j];
            }
        }
        let wq = inv2(qd);
        for k in 0..steps {
            // residual x_{k+1} − Φ x_k = J [x_k; x_{k+1}], J = [−Φ, I]
            let mut jm = [[0.0; 4]; 2];
            for i in 0..2 {
                for j in 0..2 {
                    jm[i][j] = -phi[i][j];
                }
                jm[i][2 + i] = 1.0;
            }
            for a in 0..4 {
                for b in 0..4 {
                    let mut v = 0.0;
                    for i in 0..2 {
                        for j in 0..2 {
                            v += jm[i][a] * wq[i][j] * jm[j][b];
                        }
                    }
                    h.add_at(2 * k + a, 2 * k + b, v);
                }
            }
        }
        for (k, zk) in z.iter().enumerate() {
            if let Some(zk) = zk {
                h.add_at(2 * k, 2 * k, 1.0 / r);
                g[2 * k] += zk / r;
            }
        }
        let l = dense::cholesky(&h).expect("normal equations are positive definite");
        dense::cholesky_solve(&l, &mut g);
        for k in 0..=steps {
            for i in 0..2 {
                let d = smoothed[k][i] - g[2 * k + i];
                assert!(
                    d.abs() < 1e-9,
                    "step {k} state {i}: RTS {} vs batch {} ({d:e})",
                    smoothed[k][i],
                    g[2 * k + i]
                );
            }
        }
        // And the smoothing did something: the gap's middle differs from
        // the forward filter by more than the tolerance.
        assert!((smoothed[20][0] - nominals[20][0]).abs() > 1e-3);
    }

    /// A rollback cuts the record back and writes the epochs after again:
    /// the re-written records replace the old, and none of the old remain
    /// (records bigger than the write buffer's block, so that some of the
    /// cut ones were already on disk).
    #[test]
    fn a_truncated_record_file_reads_back_what_was_written_after() {
        let dir = std::env::temp_dir();
        let len = 40_000;
        let mut f = RecordFile::create(&dir, "truncate", len).unwrap();
        for k in 0..10 {
            f.push(&vec![k as f64; len]).unwrap();
        }
        f.truncate(4).unwrap();
        assert_eq!(f.len(), 4);
        for k in 4..7 {
            f.push(&vec![100.0 + k as f64; len]).unwrap();
        }
        assert_eq!(f.len(), 7);
        assert_eq!(f.bytes(), (7 * len * 8) as u64);
        for k in 0..7 {
            let want = if k < 4 { k as f64 } else { 100.0 + k as f64 };
            let got = f.get(k).unwrap();
            assert!(got.iter().all(|v| *v == want), "record {k}: {}", got[0]);
        }
        assert!(f.get(7).is_err());
        // Once read, the file is closed for writing: no cut then.
        assert!(f.truncate(2).is_err());
    }

    #[test]
    fn record_file_reads_back_in_both_directions() {
        let dir = std::env::temp_dir();
        let mut f = RecordFile::create(&dir, "test", 3).unwrap();
        let count = 200_000;
        for k in 0..count {
            f.push(&[k as f64, -(k as f64), 0.5]).unwrap();
        }
        for k in (0..count).rev().step_by(7) {
            assert_eq!(f.get(k).unwrap(), &[k as f64, -(k as f64), 0.5]);
        }
        for k in (0..count).step_by(5) {
            assert_eq!(f.get(k).unwrap()[0], k as f64);
        }
        assert!(f.get(count).is_err());
        let path = f.path.clone();
        drop(f);
        assert!(!path.exists());
    }
}
