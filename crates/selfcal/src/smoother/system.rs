//! The batch's normal equations in their chain-and-arrow layout ([`System`]), the
//! elimination of the poses in time order, the damped step and the marginal covariance.

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// `n` zero 3x3 blocks.
pub(super) fn vec3x3(n: usize) -> Vec<Matrix3<f64>> {
    alloc::vec![Matrix3::zeros(); n]
}

/// A step of every unknown.
#[derive(Debug)]
pub(super) struct Step {
    pub(super) poses: Vec<Vector3<f64>>,
    pub(super) camera: Vec<f64>,
    pub(super) landmarks: Vec<Vector3<f64>>,
}

/// The normal equations: block-tridiagonal poses with an arrow `[C, landmarks]`.
#[derive(Debug)]
pub(super) struct System {
    pub(super) d: Vec<Matrix3<f64>>,
    /// Coupling of pose `k` with pose `k + 1`.
    pub(super) e: Vec<Matrix3<f64>>,
    /// Coupling of pose `k` with the arrow.
    pub(super) f: Vec<DMatrix<f64>>,
    pub(super) b: Vec<Vector3<f64>>,
    /// Arrow columns that pose `k` (with the fill of the poses before it) touches: a prefix.
    pub(super) active: Vec<usize>,
    pub(super) z: DMatrix<f64>,
    pub(super) bz: DVector<f64>,
    pub(super) m: usize,
    pub(super) observations: usize,
    pub(super) outliers: usize,
}

impl System {
    /// Eliminates the poses but the last in time order (damped by `lambda`); returns the
    /// reduced system over `[last pose, arrow]` and what back-substitution needs.
    #[allow(clippy::type_complexity)]
    pub(super) fn eliminate(
        &self,
        lambda: f64,
    ) -> Option<(
        DMatrix<f64>,
        DVector<f64>,
        Vec<(Matrix3<f64>, Matrix3<f64>, DMatrix<f64>, Vector3<f64>)>,
    )> {
        let pv = self.d.len();
        let w = self.z.nrows();
        let damp3 = |m: &Matrix3<f64>| {
            let mut m = *m;
            for i in 0..3 {
                m[(i, i)] += lambda * m[(i, i)] + 1e-12;
            }
            m
        };
        let mut z = self.z.clone();
        for i in 0..w {
            z[(i, i)] += lambda * self.z[(i, i)] + 1e-12;
        }
        let mut bz = self.bz.clone();
        let mut d_next = self.d.first().map(&damp3);
        let mut f_next = self.f.first().cloned();
        let mut b_next = self.b.first().copied();
        let mut back = Vec::with_capacity(pv.saturating_sub(1));
        for k in 0..pv.saturating_sub(1) {
            let dk = d_next.take()?;
            let fk = f_next.take()?;
            let bk = b_next.take()?;
            let dinv = dk.cholesky()?.inverse();
            let ek = *self.e.get(k)?;
            let a = *self.active.get(k)?;
            let g = dinv * ek; // D^-1 E
            let h = dinv * fk.columns(0, a); // D^-1 F (3 x a)
            let db = dinv * bk;
            // Next pose.
            let mut dn = damp3(self.d.get(k + 1)?) - ek.transpose() * g;
            dn = 0.5 * (dn + dn.transpose());
            let mut fnx = self.f.get(k + 1)?.clone();
            {
                let mut view = fnx.columns_mut(0, a);
                view.gemm(-1.0, &ek.transpose(), &h, 1.0);
            }
            let bn = self.b.get(k + 1)? - ek.transpose() * db;
            // Arrow.
            {
                let fa = fk.columns(0, a);
                let mut zv = z.view_mut((0, 0), (a, a));
                zv.gemm_tr(-1.0, &fa, &h, 1.0);
                let mut bv = bz.rows_mut(0, a);
                bv.gemv_tr(-1.0, &fa, &db, 1.0);
            }
            let mut hfull = DMatrix::zeros(3, a);
            hfull.copy_from(&h);
            back.push((dinv, g, hfull, db));
            d_next = Some(dn);
            f_next = Some(fnx);
            b_next = Some(bn);
        }
        // Reduced system over [last pose, arrow].
        let r = 3 + w;
        let mut big = DMatrix::zeros(r, r);
        let mut rhs = DVector::zeros(r);
        if let (Some(dl), Some(fl), Some(bl)) = (d_next, f_next, b_next) {
            big.view_mut((0, 0), (3, 3)).copy_from(&dl);
            big.view_mut((0, 3), (3, w)).copy_from(&fl);
            big.view_mut((3, 0), (w, 3)).copy_from(&fl.transpose());
            rhs.rows_mut(0, 3).copy_from(&bl);
        } else {
            for i in 0..3 {
                big[(i, i)] = 1.0;
            }
        }
        big.view_mut((3, 3), (w, w)).copy_from(&z);
        rhs.rows_mut(3, w).copy_from(&bz);
        Some((big, rhs, back))
    }

    /// The batch's Levenberg-Marquardt step (its eq. (2)): every unknown's step from the
    /// normal equations damped by `lambda` (`H + lambda diag(H)`, plus `1e-12` on the
    /// diagonal), the poses eliminated in time order and back-substituted. `None` when the
    /// damped system is not positive definite or the step not finite (the caller raises
    /// `lambda`).
    pub(super) fn lm_step(&self, lambda: f64) -> Option<Step> {
        let (big, rhs, back) = self.eliminate(lambda)?;
        let pv = self.d.len();
        let w = self.z.nrows();
        let sol = big.cholesky()?.solve(&rhs);
        if !sol.iter().all(|v| v.is_finite()) {
            return None;
        }
        let zsol = sol.rows(3, w).into_owned();
        let mut poses = alloc::vec![Vector3::zeros(); pv];
        if let Some(last) = poses.last_mut() {
            *last = Vector3::new(sol[0], sol[1], sol[2]);
        }
        for k in (0..pv.saturating_sub(1)).rev() {
            let (_dinv, g, h, db) = back.get(k)?;
            let next = *poses.get(k + 1)?;
            let a = h.ncols();
            let x = db - g * next - h * zsol.rows(0, a);
            *poses.get_mut(k)? = x;
        }
        let camera = zsol.rows(0, self.m).iter().copied().collect();
        let nl = (w - self.m) / 3;
        let landmarks = (0..nl)
            .map(|j| {
                let o = self.m + 3 * j;
                Vector3::new(zsol[o], zsol[o + 1], zsol[o + 2])
            })
            .collect();
        Some(Step {
            poses,
            camera,
            landmarks,
        })
    }

    /// Joint covariance of `[last pose, C, landmarks]`: the inverse of the reduced system.
    pub(super) fn marginal_covariance(&self) -> Option<DMatrix<f64>> {
        let (big, _, _) = self.eliminate(0.0)?;
        let mut cov = big.cholesky()?.inverse();
        if self.d.is_empty() {
            for i in 0..3 {
                for j in 0..cov.ncols() {
                    cov[(i, j)] = 0.0;
                    cov[(j, i)] = 0.0;
                }
            }
        }
        let cov = 0.5 * (&cov + cov.transpose());
        cov.iter().all(|v| v.is_finite()).then_some(cov)
    }
}
