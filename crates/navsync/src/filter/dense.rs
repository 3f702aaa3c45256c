//! Small row-major dense matrices for the error-state filter, with the few
//! kernels it needs: products by a matrix given as sparse rows (the state
//! transition and measurement matrices are mostly zeros), Cholesky
//! factorisation, and symmetrisation. Written for n ≈ 20–30 and m ≤ 10.

#![warn(missing_docs)]

/// A row-major `rows × cols` matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Mat {
    /// Number of rows.
    pub rows: usize,
    pub(crate) cols: usize,
    /// The entries, row by row (`rows × cols` of them).
    pub data: Vec<f64>,
}

impl Mat {
    /// A `rows` × `cols` matrix of zeros.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Mat {
            rows,
            cols,
            data: vec![0.0; rows * cols],
        }
    }

    pub(crate) fn identity(n: usize) -> Self {
        let mut m = Mat::zeros(n, n);
        for i in 0..n {
            m.data[i * n + i] = 1.0;
        }
        m
    }

    /// Element (`r`, `c`).
    #[inline]
    pub fn get(&self, r: usize, c: usize) -> f64 {
        self.data[r * self.cols + c]
    }

    /// Sets element (`r`, `c`).
    #[inline]
    pub fn set(&mut self, r: usize, c: usize, v: f64) {
        self.data[r * self.cols + c] = v;
    }

    #[inline]
    pub(crate) fn add_at(&mut self, r: usize, c: usize, v: f64) {
        self.data[r * self.cols + c] += v;
    }

    /// Row `r`.
    #[inline]
    pub fn row(&self, r: usize) -> &[f64] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }

    #[inline]
    pub(crate) fn row_mut(&mut self, r: usize) -> &mut [f64] {
        &mut self.data[r * self.cols..(r + 1) * self.cols]
    }

    /// Writes a 3×3 block with its top-left corner at (r, c).
    pub(crate) fn set_block3(&mut self, r: usize, c: usize, b: &nalgebra::Matrix3<f64>) {
        for i in 0..3 {
            for j in 0..3 {
                self.set(r + i, c + j, b[(i, j)]);
            }
        }
    }

    /// Reads the 3×3 block at (r, c).
    pub(crate) fn block3(&self, r: usize, c: usize) -> nalgebra::Matrix3<f64> {
        nalgebra::Matrix3::from_fn(|i, j| self.get(r + i, c + j))
    }

    /// Transpose into `out` (resized as needed).
    pub(crate) fn transpose_into(&self, out: &mut Mat) {
        out.rows = self.cols;
        out.cols = self.rows;
        out.data.resize(self.data.len(), 0.0);
        for i in 0..self.rows {
            for j in 0..self.cols {
                out.data[j * self.rows + i] = self.data[i * self.cols + j];
            }
        }
    }

    /// Makes a square matrix exactly symmetric: (M + Mᵀ)/2.
    pub(crate) fn symmetrize(&mut self) {
        let n = self.rows;
        for i in 0..n {
            for j in (i + 1)..n {
                let v = 0.5 * (self.data[i * n + j] + self.data[j * n + i]);
                self.data[i * n + j] = v;
                self.data[j * n + i] = v;
            }
        }
    }
}

/// The nonzero pattern of a matrix by rows: for each row, the columns that
/// hold nonzeros.
#[derive(Clone, Debug, Default)]
pub(crate) struct RowPattern {
    pub(crate) starts: Vec<usize>,
    pub(crate) cols: Vec<usize>,
}

impl RowPattern {
    /// Scans `m` for nonzeros.
    pub(crate) fn scan(m: &Mat, out: &mut RowPattern) {
        out.starts.clear();
        out.cols.clear();
        for i in 0..m.rows {
            out.starts.push(out.cols.len());
            for (j, &v) in m.row(i).iter().enumerate() {
                if v != 0.0 {
                    out.cols.push(j);
                }
            }
        }
        out.starts.push(out.cols.len());
    }

    #[inline]
    pub(crate) fn row(&self, i: usize) -> &[usize] {
        &self.cols[self.starts[i]..self.starts[i + 1]]
    }
}

/// `out = a · b` where `a` is given with its nonzero pattern (rows of `a`
/// mostly zero) and `b` is dense. Inner loop runs along contiguous rows.
pub(crate) fn sparse_mul(a: &Mat, pat: &RowPattern, b: &Mat, out: &mut Mat) {
    debug_assert_eq!(a.cols, b.rows);
    out.rows = a.rows;
    out.cols = b.cols;
    out.data.clear();
    out.data.resize(a.rows * b.cols, 0.0);
    let bc = b.cols;
    for i in 0..a.rows {
        let out_row = &mut out.data[i * bc..(i + 1) * bc];
        for &k in pat.row(i) {
            let aik = a.data[i * a.cols + k];
            let b_row = &b.data[k * bc..(k + 1) * bc];
            for (o, &bv) in out_row.iter_mut().zip(b_row) {
                *o += aik * bv;
            }
        }
    }
}

/// `out = a · bᵀ` where both are dense (`a`: r×k, `b`: c×k).
pub(crate) fn mul_transpose(a: &Mat, b: &Mat, out: &mut Mat) {
    debug_assert_eq!(a.cols, b.cols);
    out.rows = a.rows;
    out.cols = b.rows;
    out.data.clear();
    out.data.resize(a.rows * b.rows, 0.0);
    for i in 0..a.rows {
        let ar = a.row(i);
        for j in 0..b.rows {
            let br = b.row(j);
            out.data[i * b.rows + j] = ar.iter().zip(br).map(|(x, y)| x * y).sum();
        }
    }
}

/// Dense `out = a · b`.
pub(crate) fn mul(a: &Mat, b: &Mat, out: &mut Mat) {
    debug_assert_eq!(a.cols, b.rows);
    out.rows = a.rows;
    out.cols = b.cols;
    out.data.clear();
    out.data.resize(a.rows * b.cols, 0.0);
    for i in 0..a.rows {
        for k in 0..a.cols {
            let aik = a.data[i * a.cols + k];
            if aik == 0.0 {
                continue;
            }
            let b_row = &b.data[k * b.cols..(k + 1) * b.cols];
            let out_row = &mut out.data[i * b.cols..(i + 1) * b.cols];
            for (o, &bv) in out_row.iter_mut().zip(b_row) {
                *o += aik * bv;
            }
        }
    }
}

/// Lower Cholesky factor L (row-major) of a symmetric positive-definite
/// matrix, or `None` when it is not positive definite.
pub(crate) fn cholesky(m: &Mat) -> Option<Mat> {
    let n = m.rows;
    let mut l = Mat::zeros(n, n);
    for j in 0..n {
        let mut d = m.get(j, j);
        for k in 0..j {
            d -= l.get(j, k) * l.get(j, k);
        }
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        let d = d.sqrt();
        l.set(j, j, d);
        for i in (j + 1)..n {
            let mut s = m.get(i, j);
            for k in 0..j {
                s -= l.get(i, k) * l.get(j, k);
            }
            l.set(i, j, s / d);
        }
    }
    Some(l)
}

/// Solves L Lᵀ x = b in place for one right-hand side.
pub(crate) fn cholesky_solve(l: &Mat, b: &mut [f64]) {
    let n = l.rows;
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l.get(i, k) * b[k];
        }
        b[i] = s / l.get(i, i);
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in (i + 1)..n {
            s -= l.get(k, i) * b[k];
        }
        b[i] = s / l.get(i, i);
    }
}

/// Inverse of a symmetric positive-definite matrix from its Cholesky factor.
pub(crate) fn cholesky_inverse(l: &Mat) -> Mat {
    let n = l.rows;
    let mut inv = Mat::zeros(n, n);
    let mut col = vec![0.0; n];
    for j in 0..n {
        col.iter_mut().for_each(|x| *x = 0.0);
        col[j] = 1.0;
        cholesky_solve(l, &mut col);
        for i in 0..n {
            inv.set(i, j, col[i]);
        }
    }
    inv
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_mat(r: usize, c: usize, seed: u64, density: f64) -> Mat {
        let mut s = seed;
        let mut m = Mat::zeros(r, c);
        for v in m.data.iter_mut() {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (s >> 11) as f64 / (1u64 << 53) as f64;
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let w = (s >> 11) as f64 / (1u64 << 53) as f64;
            if w < density {
                *v = u - 0.5;
            }
        }
        m
    }

    #[test]
    fn sparse_product_equals_dense() {
        let a = random_mat(21, 21, 1, 0.3);
        let b = random_mat(21, 21, 2, 1.0);
        let mut pat = RowPattern::default();
        RowPattern::scan(&a, &mut pat);
        let mut s = Mat::zeros(0, 0);
        let mut d = Mat::zeros(0, 0);
        sparse_mul(&a, &pat, &b, &mut s);
        mul(&a, &b, &mut d);
        for (x, y) in s.data.iter().zip(&d.data) {
            assert!((x - y).abs() < 1e-12);
        }
        let mut bt = Mat::zeros(0, 0);
        b.transpose_into(&mut bt);
        let mut e = Mat::zeros(0, 0);
        mul_transpose(&a, &bt, &mut e);
        for (x, y) in e.data.iter().zip(&d.data) {
            assert!((x - y).abs() < 1e-12);
        }
    }

    #[test]
    fn cholesky_inverts_spd_and_rejects_indefinite() {
        let a = random_mat(5, 5, 3, 1.0);
        let mut spd = Mat::zeros(0, 0);
        mul_transpose(&a, &a, &mut spd);
        for i in 0..5 {
            spd.add_at(i, i, 0.1);
        }
        let l = cholesky(&spd).expect("spd");
        let inv = cholesky_inverse(&l);
        let mut prod = Mat::zeros(0, 0);
        mul(&spd, &inv, &mut prod);
        for i in 0..5 {
            for j in 0..5 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((prod.get(i, j) - want).abs() < 1e-9);
            }
        }
        let mut bad = spd.clone();
        bad.set(2, 2, -1.0);
        assert!(cholesky(&bad).is_none());
    }
}
