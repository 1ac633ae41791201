//! Eq. (6)-(7), the update: each landmark's innovation gated on its own NIS, then the gain
//! ([`gain`], eq. (6)) and the correction of the state and the covariance
//! ([`correct_state`] and [`covariance_correction`], eq. (7)), either one landmark at a time
//! (small states) or as one batch; the crate docs say why it has this form. The arithmetic
//! is in `crate::kernels`.

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix4, Vector4};
use rig_model::camera::{Param, wrap_angle};
use rig_model::{Measurement, N_PARAMS};

use crate::error::Error;
use crate::filter::{
    AUTO_JOSEPH_MAX_STATES, CameraUpdate, CovarianceUpdate, Ekf, Gated, SEQUENTIAL_MAX_STATES,
    UpdateReport,
};
use crate::kernels::{
    LANES, MAX_INVOLVED, Obs, Workspace, cholesky4, compact, diagonal_change, gain_factors,
    gain_factors4, innovation_products, mahalanobis4, observation_products,
    rank_update_lower_padded,
};
use crate::landmarks::LandmarkId;
use crate::linalg::rank_update_lower;
use crate::state::at;

/// What eq. (6)'s gain is computed from: the innovation covariance `S` (with `A = P H^T`
/// already in the workspace) and the innovation `nu`.
enum Innovation<'a> {
    /// One landmark: `S` by rows (4x4) and its innovation.
    One {
        s: &'a [[f64; 4]; 4],
        nu: &'a [f64; 4],
    },
    /// A batch of `observations` landmarks: `S` (`d x d`, `d = 4 observations`) in the
    /// workspace, the innovations stacked.
    Batch { observations: usize, nu: &'a [f64] },
}

/// Eq. (6): the gain `K = P H^T S^-1 = A S^-1`, through the Cholesky factor `S = L L^T`, as
/// the factors eq. (7) needs, into the workspace: `W = A L^-T`, the correction `dx = K nu`,
/// and for the Joseph form `lhs = [K S - A, -K]`, `rhs = [K, A]`. `n` rows (the state, or its
/// padded copy); fails when `S` is not positive definite.
fn gain(
    n: usize,
    innovation: Innovation<'_>,
    joseph: bool,
    ws: &mut Workspace,
) -> Result<(), Error> {
    match innovation {
        Innovation::One { s, nu } => {
            let l4 =
                cholesky4(s).ok_or(Error::InnovationNotPositiveDefinite { observations: 1 })?;
            gain_factors4(
                n,
                &l4,
                s,
                nu,
                joseph,
                &ws.a,
                &mut ws.w,
                &mut ws.dx,
                &mut ws.lhs,
                &mut ws.rhs,
            );
        }
        Innovation::Batch { observations, nu } => {
            let d = 4 * observations;
            let chol = nalgebra::Cholesky::new(DMatrix::from_column_slice(d, d, &ws.s))
                .ok_or(Error::InnovationNotPositiveDefinite { observations })?;
            gain_factors(
                n,
                d,
                chol.l_dirty().as_slice(),
                &ws.s,
                nu,
                joseph,
                &ws.a,
                &mut ws.w,
                &mut ws.y,
                &mut ws.dx,
                &mut ws.lhs,
                &mut ws.rhs,
            );
        }
    }
    Ok(())
}

/// Eq. (7), the covariance: `P+ = (I - K H) P (I - K H)^T + K R K^T` as the symmetric rank
/// update `lower(P+) = lower(P) + alpha lhs rhs^T` of the gain's factors, returned as
/// `(lhs, rhs, alpha)`: the Joseph form `[K S - A, -K] [K, A]^T` (alpha 1), or the factored
/// `P - W W^T` (the optimal gain's, alpha -1). Checked before anything is applied: every
/// variance of `p` (`n x n`) stays positive (or zero, the start pose before the first
/// prediction), computed from the factors in O(n c) into `diagonal`.
fn covariance_correction<'a>(
    p: &[f64],
    n: usize,
    joseph: bool,
    (lhs, rhs, w): (&'a [f64], &'a [f64], &'a [f64]),
    diagonal: &mut Vec<f64>,
) -> Result<(&'a [f64], &'a [f64], f64), Error> {
    let (lhs, rhs, alpha) = if joseph {
        (lhs, rhs, 1.0)
    } else {
        (w, w, -1.0)
    };
    diagonal_change(n, lhs, rhs, alpha, diagonal);
    check_variances(p, n, diagonal)?;
    Ok((lhs, rhs, alpha))
}

/// Eq. (7), the state: `x+ = x + K nu` (`dx = K nu` from the gain), the heading wrapped into
/// `(-pi, pi]`.
fn correct_state(x: &mut DVector<f64>, dx: &[f64]) {
    for (xi, dxi) in x.iter_mut().zip(dx) {
        *xi += dxi;
    }
    x[2] = wrap_angle(x[2]);
}

/// Every variance stays positive after adding `change` to the diagonal of `p` (or stays zero:
/// the start pose before the first prediction).
fn check_variances(p: &[f64], n: usize, change: &[f64]) -> Result<(), Error> {
    for (i, c) in change.iter().enumerate() {
        let before = p.get(at(n, i, i)).copied().unwrap_or(f64::NAN);
        let after = before + c;
        if !(after > 0.0 || (after == 0.0 && before == 0.0)) {
            return Err(Error::VarianceNotPositive {
                index: i,
                before,
                after,
            });
        }
    }
    Ok(())
}

/// The corrected state is finite.
fn check_state(x: &DVector<f64>, dx: &[f64]) -> Result<(), Error> {
    for (i, (&xi, &dxi)) in x.iter().zip(dx).enumerate() {
        if !(xi + dxi).is_finite() {
            return Err(Error::StateNotFinite { index: i });
        }
    }
    Ok(())
}

impl Ekf {
    /// Holds estimated camera parameters for the updates to come: they are considered, not
    /// refined (their gain rows are zero, as with [`CameraUpdate::Consider`] for all of them):
    /// value and variance stay, their covariance is carried into the pose and landmarks. For
    /// a parameter the data cannot inform yet (the baseline on a vehicle that has not moved:
    /// docs/real-images.md), so that model errors elsewhere cannot pull it. Parameters not
    /// estimated are ignored.
    pub fn set_held(&mut self, params: &[Param]) {
        self.held = [false; N_PARAMS];
        for p in params {
            if self.estimated.contains(p)
                && let Some(h) = self.held.get_mut(p.index())
            {
                *h = true;
            }
        }
    }

    /// The estimated parameters held ([`Ekf::set_held`]).
    pub fn held(&self) -> Vec<Param> {
        self.estimated
            .iter()
            .copied()
            .filter(|p| self.held.get(p.index()).copied().unwrap_or(false))
            .collect()
    }

    /// Camera state rows whose gain is zero: all with [`CameraUpdate::Consider`], else the
    /// held ones.
    fn frozen(&self, k: usize) -> bool {
        self.settings.camera_update == CameraUpdate::Consider
            || self
                .estimated
                .get(k)
                .is_some_and(|p| self.held.get(p.index()).copied().unwrap_or(false))
    }

    /// Whether the next update uses the Joseph form (camera considered or held, or a small
    /// state in [`CovarianceUpdate::Auto`]): it costs about twice the factored form.
    pub fn uses_joseph(&self) -> bool {
        self.joseph()
    }

    fn joseph(&self) -> bool {
        if self.settings.camera_update == CameraUpdate::Consider || self.held.iter().any(|h| *h) {
            return true;
        }
        match self.settings.covariance_update {
            CovarianceUpdate::Joseph => true,
            CovarianceUpdate::Factored => false,
            CovarianceUpdate::Auto => self.x.len() <= AUTO_JOSEPH_MAX_STATES,
        }
    }

    /// Eq. (6)-(7): updates with a batch of landmark measurements `(uL, vL, uR, vR)`.
    ///
    /// Each observation is linearised at the current estimate (eq. (8)) and gated on its own
    /// NIS first; the accepted ones are applied together.
    /// On an error nothing changes (the health counts refused updates).
    pub fn update(&mut self, batch: &[(LandmarkId, Measurement)]) -> Result<UpdateReport, Error> {
        let mut slots: Vec<usize> = Vec::with_capacity(batch.len());
        for (id, z) in batch {
            if let Some(&value) = z.iter().find(|v| !v.is_finite()) {
                return Err(Error::NonFiniteMeasurement { id: *id, value });
            }
            let s = self.slot(*id).ok_or(Error::UnknownLandmark { id: *id })?;
            if slots.contains(&s) {
                return Err(Error::DuplicateObservation { id: *id });
            }
            slots.push(s);
        }
        let camera = self.camera();
        let pose = self.pose();
        // Linearise every observation at the current estimate; one that cannot be projected
        // is rejected outright.
        let mut obs: Vec<Obs> = Vec::with_capacity(batch.len());
        let mut nis: Vec<f64> = alloc::vec![f64::INFINITY; batch.len()];
        let mut projected: Vec<usize> = Vec::with_capacity(batch.len());
        for (b, (&s, (_, z))) in slots.iter().zip(batch).enumerate() {
            if let Ok((predicted, mut o)) = self.observation_model(s, &camera, &pose) {
                // Eq. (6)'s innovation, nu = z - h(x).
                let nu = z - predicted;
                o.nu = [nu[0], nu[1], nu[2], nu[3]];
                o.r = self.measurement_variances(&predicted);
                obs.push(o);
                projected.push(b);
            }
        }
        let mut ws = core::mem::take(&mut self.workspace);
        let result = self.gate_and_update(&obs, &projected, &mut nis, &mut ws);
        self.workspace = ws;
        if let Err(e) = result {
            self.health.refused_updates += 1;
            return Err(e);
        }
        let mut report = UpdateReport::default();
        if !batch.is_empty() {
            self.health.updates += 1;
        }
        for ((&s, (id, _)), &v) in slots.iter().zip(batch).zip(&nis) {
            let accepted = v <= self.gate;
            self.health.record(accepted.then_some(v));
            let gated = Gated { id: *id, nis: v };
            if accepted {
                report.accepted.push(gated);
            } else {
                report.rejected.push(gated);
            }
            if let Some(slot) = self.landmarks.get_mut(s) {
                if accepted {
                    slot.observations += 1;
                    slot.rejections_in_a_row = 0;
                } else {
                    slot.rejections_in_a_row = slot.rejections_in_a_row.saturating_add(1);
                }
            }
        }
        let limit = self.settings.max_consecutive_rejections;
        if self
            .landmarks
            .iter()
            .any(|l| l.rejections_in_a_row >= limit)
        {
            let doomed: Vec<LandmarkId> = self
                .landmarks
                .iter()
                .filter(|l| l.rejections_in_a_row >= limit)
                .map(|l| l.id)
                .collect();
            for id in doomed {
                if self.remove_landmark(id).is_ok() {
                    report.removed.push(id);
                }
            }
        }
        Ok(report)
    }

    /// `A`, `S`, the gate (each observation's NIS into `nis[projected[j]]`), and the batch
    /// update of the accepted ones. Checks everything before touching the state; on an error
    /// the state is as it was.
    fn gate_and_update(
        &mut self,
        obs: &[Obs],
        projected: &[usize],
        nis: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), Error> {
        if obs.is_empty() {
            return Ok(());
        }
        let n = self.x.len();
        if n <= SEQUENTIAL_MAX_STATES {
            // Gate each observation on the prior, then apply the accepted ones in turn.
            let mut keep: Vec<&Obs> = Vec::with_capacity(obs.len());
            for (j, o) in obs.iter().enumerate() {
                let s4 = self.innovation_covariance(o);
                let l = cholesky4(&core::array::from_fn(|r| {
                    core::array::from_fn(|c| s4[(r, c)])
                }))
                .ok_or(Error::InnovationNotPositiveDefinite { observations: 1 })?;
                let v = mahalanobis4(&l, &o.nu);
                if let Some(slot) = projected.get(j).and_then(|&b| nis.get_mut(b)) {
                    *slot = if v.is_finite() { v } else { f64::INFINITY };
                }
                if v.is_finite() && v <= self.gate {
                    keep.push(o);
                }
            }
            return self.sequential_update(&keep, ws);
        }
        innovation_products(self.p.as_slice(), n, obs, ws);
        let mut d = 4 * obs.len();
        if ws.s.iter().any(|v| !v.is_finite()) {
            return Err(Error::InnovationNotPositiveDefinite {
                observations: obs.len(),
            });
        }
        // Gate: each observation's NIS with its own 4x4 block of S.
        let mut keep: Vec<usize> = Vec::with_capacity(obs.len());
        for (j, o) in obs.iter().enumerate() {
            let block = Matrix4::from_fn(|r, c| ws.s[(4 * j + c) * d + 4 * j + r]);
            let chol = block
                .cholesky()
                .ok_or(Error::InnovationNotPositiveDefinite { observations: 1 })?;
            let nu = Vector4::from(o.nu);
            let v = nu.dot(&chol.solve(&nu));
            if let Some(slot) = projected.get(j).and_then(|&b| nis.get_mut(b)) {
                *slot = if v.is_finite() { v } else { f64::INFINITY };
            }
            if v.is_finite() && v <= self.gate {
                keep.push(j);
            }
        }
        if keep.is_empty() {
            return Ok(());
        }
        if keep.len() < obs.len() {
            compact(n, d, &keep, &mut ws.a, &mut ws.s);
            d = 4 * keep.len();
        }
        let nu: Vec<f64> = keep
            .iter()
            .filter_map(|&j| obs.get(j))
            .flat_map(|o| o.nu)
            .collect();
        let joseph = self.joseph();
        let innovation = Innovation::Batch {
            observations: keep.len(),
            nu: &nu,
        };
        gain(n, innovation, joseph, ws)?;
        self.freeze_camera_rows(n, d, ws);
        // Checks before committing: every variance stays positive (O(n d) from the factors),
        // the new state is finite.
        let (lhs, rhs, alpha) = covariance_correction(
            self.p.as_slice(),
            n,
            joseph,
            (&ws.lhs, &ws.rhs, &ws.w),
            &mut ws.y,
        )?;
        check_state(&self.x, &ws.dx)?;
        // Commit.
        rank_update_lower(
            self.p.as_mut_slice(),
            n,
            lhs,
            rhs,
            lhs.len() / n.max(1),
            alpha,
        );
        correct_state(&mut self.x, &ws.dx);
        Ok(())
    }

    /// [`CameraUpdate::Consider`]: the camera rows of the gain set to zero in the update's
    /// factors (Joseph form, `n` rows, `d` measurement columns): `dx_c = 0`, and in
    /// `lhs = [K S - A, -K]`, `rhs = [K, A]` the camera rows become `[-A_c, 0]` and `[0, A_c]`,
    /// so that `P_cc` is left as it was and `P_xc` becomes `P_xc - K_x A_c^T`.
    fn freeze_camera_rows(&self, n: usize, d: usize, ws: &mut Workspace) {
        let c0 = self.camera_offset();
        for (k, i) in (c0..c0 + self.estimated.len()).enumerate() {
            if !self.frozen(k) {
                continue;
            }
            if let Some(v) = ws.dx.get_mut(i) {
                *v = 0.0;
            }
            for c in 0..d {
                let a = ws.rhs.get((d + c) * n + i).copied().unwrap_or(0.0);
                if let Some(v) = ws.lhs.get_mut(c * n + i) {
                    *v = -a;
                }
                if let Some(v) = ws.lhs.get_mut((d + c) * n + i) {
                    *v = 0.0;
                }
                if let Some(v) = ws.rhs.get_mut(c * n + i) {
                    *v = 0.0;
                }
            }
        }
    }

    /// The accepted observations applied one landmark at a time, for small states: exactly
    /// the batch update (the linearisation stays at the prior estimate; each innovation is
    /// corrected by `H_j dx` for the corrections before it), without the batch's `O(n k^2)`
    /// gain terms, which for the paper's 19 states and 20 measurements are as large as the
    /// rank update itself. Works on a copy of `P` so that a failure changes nothing.
    fn sequential_update(&mut self, obs: &[&Obs], ws: &mut Workspace) -> Result<(), Error> {
        if obs.is_empty() {
            return Ok(());
        }
        // The work is done on a copy of P padded with zero states to whole vectors: a state
        // with zero variance and no correlation is left exactly as it is by the update.
        let n = self.x.len();
        let np = n.next_multiple_of(LANES);
        let joseph = self.joseph();
        ws.p.clear();
        ws.p.resize(np * np, 0.0);
        for (dst, src) in
            ws.p.chunks_exact_mut(np)
                .zip(self.p.as_slice().chunks_exact(n))
        {
            dst[..n].copy_from_slice(src);
        }
        ws.dx_total.clear();
        ws.dx_total.resize(np, 0.0);
        let mut s16 = [0.0; 16];
        for o in obs {
            observation_products(&ws.p, np, o, &mut ws.a, &mut s16);
            let s4: [[f64; 4]; 4] =
                core::array::from_fn(|r| core::array::from_fn(|c| s16[c * 4 + r]));
            // nu - H dx: the innovation at the estimate corrected so far.
            let mut nu = o.nu;
            for (r, v) in nu.iter_mut().enumerate() {
                for (h, &c) in o.h[r].iter().zip(&o.cols).take(o.q) {
                    *v -= h * ws.dx_total.get(c).copied().unwrap_or(0.0);
                }
            }
            gain(np, Innovation::One { s: &s4, nu: &nu }, joseph, ws)?;
            self.freeze_camera_rows(np, 4, ws);
            let (lhs, rhs, alpha) =
                covariance_correction(&ws.p, np, joseph, (&ws.lhs, &ws.rhs, &ws.w), &mut ws.y)?;
            rank_update_lower_padded(&mut ws.p, np, lhs, rhs, alpha);
            for (t, d) in ws.dx_total.iter_mut().zip(&ws.dx) {
                *t += d;
            }
        }
        check_state(&self.x, &ws.dx_total)?;
        for (dst, src) in self
            .p
            .as_mut_slice()
            .chunks_exact_mut(n)
            .zip(ws.p.chunks_exact(np))
        {
            dst.copy_from_slice(&src[..n]);
        }
        correct_state(&mut self.x, &ws.dx_total);
        Ok(())
    }

    /// Eq. (6)'s innovation covariance `S = H P H^T + R` of one observation (4x4), from the
    /// involved block of `P` only (the batch's `S` is `kernels::innovation_products`, one
    /// landmark's on the padded copy `kernels::observation_products`).
    pub(crate) fn innovation_covariance(&self, m: &Obs) -> Matrix4<f64> {
        let n = self.x.len();
        let buf = self.p.as_slice();
        let q = m.q.min(MAX_INVOLVED);
        // The involved block of P (its columns increase, so `a >= b` is in the lower triangle).
        let mut pq = [[0.0; MAX_INVOLVED]; MAX_INVOLVED];
        for (a, &ca) in m.cols.iter().enumerate().take(q) {
            for (b, &cb) in m.cols.iter().enumerate().take(a + 1) {
                // cb <= ca: (ca, cb) is in the lower triangle.
                let v = buf.get(cb * n + ca).copied().unwrap_or(f64::NAN);
                pq[a][b] = v;
                pq[b][a] = v;
            }
        }
        // T = H P_qq (4 x q), then S = T H^T.
        let mut t = [[0.0; MAX_INVOLVED]; 4];
        for (t_row, h_row) in t.iter_mut().zip(&m.h) {
            for (a, h) in h_row.iter().enumerate().take(q) {
                for (tv, pv) in t_row.iter_mut().zip(&pq[a]).take(q) {
                    *tv += h * pv;
                }
            }
        }
        let mut s = Matrix4::zeros();
        for (r, t_row) in t.iter().enumerate() {
            for (c, h_row) in m.h.iter().enumerate().skip(r) {
                let mut v: f64 = t_row.iter().zip(h_row).take(q).map(|(a, b)| a * b).sum();
                if r == c {
                    v += m.r[r];
                }
                s[(r, c)] = v;
                s[(c, r)] = v;
            }
        }
        s
    }
}
