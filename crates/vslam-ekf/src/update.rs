//! Eq. (6)-(7), the update: each landmark's innovation gated on its own NIS, then the gain
//! ([`gain`], eq. (6)) and the correction of the state and the covariance
//! ([`correct_state`] and [`covariance_correction`], eq. (7)), either one landmark at a time
//! (small states) or as one batch; the crate docs say why it has this form. The arithmetic
//! is in `crate::kernels`.

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix3, Matrix4, Vector3, Vector4};
use rig_model::camera::{Param, Pose2, wrap_angle};
use rig_model::{Measurement, N_PARAMS};

use crate::error::Error;
use crate::filter::{
    AUTO_JOSEPH_MAX_STATES, CameraUpdate, CovarianceUpdate, Ekf, FEJ_CAMERA_RELATIVE,
    FEJ_SETTLE_SIGMA_M, Gated, ITERATE_HEADING_SIGMA_RAD, ITERATE_MAX_PASSES,
    ITERATE_POSITION_SIGMA_M, ITERATE_TOLERANCE_SIGMAS, SEQUENTIAL_MAX_STATES, UpdateReport,
};
use crate::kernels::gather_columns;
use crate::kernels::{
    LANES, MAX_INVOLVED, Obs, Workspace, cholesky4, compact, diagonal_change, gain_factors,
    gain_factors4, innovation_products, mahalanobis4, observation_products,
    rank_update_lower_padded,
};
use crate::landmarks::LandmarkId;
use crate::linalg::rank_update_lower;
use crate::local::Place;
use crate::state::{LANDMARK_DIM, POSE_DIM, StateLayout, at};

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

/// `H (a - b)` over an observation's involved columns (the heading's difference wrapped).
fn state_step(a: &DVector<f64>, b: &DVector<f64>, o: &Obs) -> [f64; 4] {
    let mut out = [0.0; 4];
    for t in 0..o.q {
        let (Some(&c), Some(va), Some(vb)) = (
            o.cols.get(t),
            o.cols.get(t).and_then(|&c| a.get(c)),
            o.cols.get(t).and_then(|&c| b.get(c)),
        ) else {
            continue;
        };
        let d = if c == 2 { wrap_angle(va - vb) } else { va - vb };
        for (r, row) in o.h.iter().enumerate() {
            if let (Some(slot), Some(h)) = (out.get_mut(r), row.get(t)) {
                *slot += h * d;
            }
        }
    }
    out
}

/// A landmark seen as a point relative to the vehicle ([`Ekf::update_relative`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeObservation {
    /// The landmark.
    pub id: LandmarkId,
    /// Where it is from the vehicle: `R(theta)^T (L - p)` horizontally (x ahead, y left), its
    /// world height, metres.
    pub position: Vector3<f64>,
    /// The covariance of `position`, m^2.
    pub covariance: Matrix3<f64>,
}

/// A relative update's passes stop once no state moved by more than this (metres, radians).
const RELATIVE_STEP_TOLERANCE: f64 = 1e-6;

/// One relative observation linearised at `at` (whitened by `w`, so its rows have unit
/// variance), its innovation taken back to the prior's state `x0`:
/// `nu = W (z - h(at)) - W H (x0 - at)`. The fourth row is empty.
fn relative_obs(
    at: &DVector<f64>,
    x0: &DVector<f64>,
    li: usize,
    o: &RelativeObservation,
    w: &Matrix3<f64>,
) -> Obs {
    let g = |i: usize| at.get(i).copied().unwrap_or(0.0);
    let (px, py, theta) = (g(0), g(1), g(2));
    let (lx, ly, lz) = (g(li), g(li + 1), g(li + 2));
    let (s, c) = (libm::sin(theta), libm::cos(theta));
    let (dx, dy) = (lx - px, ly - py);
    let h = Vector3::new(c * dx + s * dy, -s * dx + c * dy, lz);
    // Columns: x, y, theta, Lx, Ly, Lz.
    let jac = nalgebra::SMatrix::<f64, 3, 6>::from_row_slice(&[
        -c,
        -s,
        -s * dx + c * dy,
        c,
        s,
        0.0, //
        s,
        -c,
        -c * dx - s * dy,
        -s,
        c,
        0.0, //
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        1.0,
    ]);
    let wh = w * jac;
    let wnu = w * (o.position - h);
    let mut out = Obs {
        cols: [0; MAX_INVOLVED],
        h: [[0.0; MAX_INVOLVED]; 4],
        q: 6,
        nu: [0.0; 4],
        r: [1.0; 4],
    };
    for (t, col) in [0, 1, 2, li, li + 1, li + 2].into_iter().enumerate() {
        if let Some(c) = out.cols.get_mut(t) {
            *c = col;
        }
        for r in 0..3 {
            if let Some(v) = out.h.get_mut(r).and_then(|row| row.get_mut(t)) {
                *v = wh[(r, t)];
            }
        }
    }
    let back = state_step(x0, at, &out);
    for r in 0..3 {
        if let Some(v) = out.nu.get_mut(r) {
            *v = wnu[r] - back[r];
        }
    }
    out
}

/// Eq. (7), the state: `x+ = x + K nu` (`dx = K nu` from the gain), the heading wrapped into
/// `(-pi, pi]`.
pub(crate) fn correct_state(x: &mut DVector<f64>, dx: &[f64]) {
    for (xi, dxi) in x.iter_mut().zip(dx) {
        *xi += dxi;
    }
    x[2] = wrap_angle(x[2]);
}

/// Every variance stays positive after adding `change` to the diagonal of `p` (or stays zero:
/// the start pose before the first prediction).
pub(crate) fn check_variances(p: &[f64], n: usize, change: &[f64]) -> Result<(), Error> {
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
pub(crate) fn check_state(x: &DVector<f64>, dx: &[f64]) -> Result<(), Error> {
    for (i, (&xi, &dxi)) in x.iter().zip(dx).enumerate() {
        if !(xi + dxi).is_finite() {
            return Err(Error::StateNotFinite { index: i });
        }
    }
    Ok(())
}

/// How far a pass moved the pose: its position change plus its heading change over
/// [`POSE_STEP_LEVER_M`], metres.
fn pose_step(from: &DVector<f64>, to: &DVector<f64>) -> f64 {
    let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
    libm::hypot(dx, dy) + POSE_STEP_LEVER_M * wrap_angle(to[2] - from[2]).abs()
}

/// The lever a heading change acts on in [`pose_step`], metres: about a ceiling camera's
/// footprint.
const POSE_STEP_LEVER_M: f64 = 5.0;

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

    /// The form a dense update of this state takes: the Joseph form with the camera
    /// considered or held, or a state of at most [`AUTO_JOSEPH_MAX_STATES`] in
    /// [`CovarianceUpdate::Auto`].
    fn dense_joseph(&self) -> bool {
        if self.settings.camera_update == CameraUpdate::Consider || self.held.iter().any(|h| *h) {
            return true;
        }
        match self.settings.covariance_update {
            CovarianceUpdate::Joseph => true,
            CovarianceUpdate::Factored => false,
            CovarianceUpdate::Auto => self.x.len() <= AUTO_JOSEPH_MAX_STATES,
        }
    }

    /// [`Self::dense_joseph`], except that in [`CovarianceUpdate::Auto`] a state large enough
    /// for local sessions (`crate::local`) is updated in the factored form, the sessions'.
    pub(crate) fn joseph(&self) -> bool {
        let local = self.settings.covariance_update == CovarianceUpdate::Auto
            && self.settings.local_margin_m > 0.0
            && self.x.len() >= crate::local::LOCAL_MIN_STATES;
        self.dense_joseph() && (self.frozen_any() || !local)
    }

    /// Some camera row's gain is zero (considered or held).
    fn frozen_any(&self) -> bool {
        self.settings.camera_update == CameraUpdate::Consider || self.held.iter().any(|h| *h)
    }

    /// Observations the next update may use ([`crate::candidates::observation_budget`]): the
    /// dense filter's budget for this state, also while local sessions make the update
    /// cheaper, so that they change its cost and not what it uses.
    pub fn observation_budget(&self) -> usize {
        crate::candidates::observation_budget(self.x.len(), self.dense_joseph())
    }

    /// Eq. (6)-(7): updates with a batch of landmark measurements `(uL, vL, uR, vR)`.
    ///
    /// Each observation is linearised at the current estimate (eq. (8)) and gated on its own
    /// NIS first; the accepted ones are applied together.
    /// On an error nothing changes (the health counts refused updates).
    ///
    /// A pair in the outer band beyond the field of use ([`Ekf::in_outer_band`]) updates only
    /// its own landmark ([`Ekf::landmark_only_update`]), after the others.
    pub fn update(&mut self, batch: &[(LandmarkId, Measurement)]) -> Result<UpdateReport, Error> {
        if !batch.iter().any(|(_, z)| self.in_outer_band(z)) {
            return self.update_within(batch);
        }
        // Checked whole before anything changes.
        self.batch_slots(batch)?;
        let mut outer: Vec<(LandmarkId, Measurement)> = Vec::new();
        let mut inner: Vec<(LandmarkId, Measurement)> = Vec::new();
        for &(id, z) in batch {
            if self.in_outer_band(&z) {
                outer.push((id, z));
            } else {
                inner.push((id, z));
            }
        }
        let mut report = self.update_within(&inner)?;
        // The far band's pairs: the least observed landmarks first, at most
        // `Settings::far_updates_per_frame` of them.
        let budget = self.settings.far_updates_per_frame;
        if budget > 0 && outer.iter().filter(|(_, z)| self.in_far_band(z)).count() > budget {
            let mut far: Vec<(u64, LandmarkId)> = outer
                .iter()
                .filter(|(_, z)| self.in_far_band(z))
                .map(|(id, _)| (self.observations_of(*id).unwrap_or(0), *id))
                .collect();
            far.sort_unstable();
            let dropped: Vec<LandmarkId> = far.iter().skip(budget).map(|(_, id)| *id).collect();
            outer.retain(|(id, _)| !dropped.contains(id));
        }
        for (id, z) in outer {
            let Some(s) = self.slot(id) else {
                continue;
            };
            let (nis, accepted) = match self.landmark_only_update(s, &z) {
                Ok(Some(r)) => r,
                Ok(None) => continue,
                Err(_) => (f64::INFINITY, false),
            };
            self.record_gated(&mut report, s, Gated { id, nis }, accepted);
        }
        Ok(report)
    }

    /// The slots of a batch's landmarks, the batch checked: every measurement finite, every
    /// landmark known and observed once.
    fn batch_slots(&self, batch: &[(LandmarkId, Measurement)]) -> Result<Vec<usize>, Error> {
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
        Ok(slots)
    }

    /// One observation's gate outcome recorded: the health's NIS window, the report, and its
    /// landmark's counts of observations and of rejections in a row.
    fn record_gated(&mut self, report: &mut UpdateReport, s: usize, gated: Gated, accepted: bool) {
        self.health.record(accepted.then_some(gated.nis));
        if let Some(slot) = self.landmarks.get_mut(s) {
            if accepted {
                slot.observations += 1;
                slot.rejections_in_a_row = 0;
            } else {
                slot.rejections_in_a_row = slot.rejections_in_a_row.saturating_add(1);
            }
        }
        if accepted {
            report.accepted.push(gated);
        } else {
            report.rejected.push(gated);
        }
        // The landmark's linearisation point follows it until it is known well enough
        // (`FEJ_SETTLE_SIGMA_M`), except while the pose is lost (`FEJ_POSITION_SIGMA_M`); with
        // `Settings::follow_points` (the default) for good, the covariance with it
        // (`Ekf::shear_linearisation_point`), and settling only lets the iterated update
        // relinearise it.
        if accepted && !self.pose_lost() {
            let follow = self.settings.follow_points;
            let settled = self.landmarks.get(s).is_some_and(|l| l.settled);
            if follow {
                self.follow_estimate(s);
            }
            if !settled {
                let camera_learned = self.camera_learned();
                let i = StateLayout::landmark(s);
                let b = self.block3(i);
                if let Some(slot) = self.landmarks.get_mut(s) {
                    if !follow {
                        slot.first = Some(self.x.fixed_rows::<3>(i).into_owned());
                    }
                    if b.diagonal().max() <= FEJ_SETTLE_SIGMA_M * FEJ_SETTLE_SIGMA_M
                        && camera_learned
                    {
                        slot.settled = true;
                    }
                }
            }
        }
    }

    /// Whether the camera's estimated parameters move a landmark by at most
    /// `FEJ_CAMERA_RELATIVE` of its distance (their sigmas over the focal length, the
    /// baseline, one radian, one metre): a landmark's linearisation point settles only then,
    /// while a camera started from nominal values still carries every landmark with it.
    fn camera_learned(&self) -> bool {
        let c = self.camera();
        let c0 = self.camera_offset();
        self.estimated.iter().enumerate().all(|(k, p)| {
            let scale = match p {
                Param::F | Param::Cx | Param::Cy => c.f,
                Param::Baseline => c.baseline,
                _ => 1.0,
            };
            p.is_vehicle() || {
                let r = libm::sqrt(self.cov(c0 + k, c0 + k).max(0.0)) / scale;
                r <= FEJ_CAMERA_RELATIVE
            }
        })
    }

    /// A stereo pair of landmark slot `s` in the outer band: a Schmidt ("consider") update of
    /// that landmark alone. The gain's rows for every other state are zero, `K = [0; K_L; 0]`
    /// with `K_L = (P H^T)_L S^-1`, and the covariance is the Joseph form's for that gain:
    /// only the landmark's rows and columns change, `P_L. -= K_L H P` (Simon, "Optimal State
    /// Estimation", 7.5). So far-out rays, whose rectified pixels carry the raw noise
    /// stretched tens of times and pulled the map's scale off when they updated everything
    /// (docs/halls.md, "A fisheye's outer band"), map their lamp and move nothing else; the
    /// pose's, the camera's and the other landmarks' uncertainty is in `S`. Returns the NIS
    /// and whether it was inside the gate (outside it nothing changes). In a local session the
    /// change is committed there (`Local::commit`, rank 6) when the involved states are
    /// active; a pair of a passive landmark is left out (`None`).
    pub(crate) fn landmark_only_update(
        &mut self,
        s: usize,
        z: &Measurement,
    ) -> Result<Option<(f64, bool)>, Error> {
        if self.settings.follow_points && !self.pose_lost() {
            self.follow_estimate(s);
        }
        let camera = self.camera();
        let pose = self.pose();
        let id = self.landmarks.get(s).map_or(LandmarkId(u64::MAX), |l| l.id);
        let (predicted, o) = self.observation_model(s, &camera, &pose)?;
        let nu = z - predicted;
        let r = self.measurement_variances(&predicted);
        let li = StateLayout::landmark(s);
        let cols: Vec<usize> = o.cols.iter().copied().take(o.q).collect();
        let active = |e: &Ekf, c: usize| {
            e.local.as_deref().and_then(|l| match l.place.get(c) {
                Some(&Place::Active(k)) => Some(k),
                _ => None,
            })
        };
        if self.local.is_some() && cols.iter().any(|&c| active(self, c).is_none()) {
            // A passive landmark (the vehicle has moved on): settling the session for one
            // far-out pair costs more than the pair is worth; it is left out.
            return Ok(None);
        }
        // P H^T over the rows that change or that S needs: the session's active rows (and
        // phi^T H^T for its passive share), or every row when dense.
        let n = self.x.len();
        let rows: Vec<usize> = match self.local.as_deref() {
            Some(l) => l.active.clone(),
            None => (0..n).collect(),
        };
        let mut pht = alloc::vec![[0.0f64; 4]; rows.len()];
        for (a, &i) in rows.iter().enumerate() {
            for (t, &c) in cols.iter().enumerate() {
                let pic = self.cov(i, c);
                for (rr, out) in pht[a].iter_mut().enumerate() {
                    *out += pic * o.h[rr][t];
                }
            }
        }
        let row_of = |i: usize| rows.iter().position(|&r| r == i);
        let mut s_mat = Matrix4::<f64>::zeros();
        for (t, &c) in cols.iter().enumerate() {
            let Some(a) = row_of(c) else {
                return Err(Error::InnovationNotPositiveDefinite { observations: 1 });
            };
            for rr in 0..4 {
                for cc in 0..4 {
                    s_mat[(rr, cc)] += o.h[rr][t] * pht[a][cc];
                }
            }
        }
        for (rr, v) in r.iter().enumerate() {
            s_mat[(rr, rr)] += v;
        }
        let s_mat = 0.5 * (s_mat + s_mat.transpose());
        let chol = s_mat
            .cholesky()
            .ok_or(Error::InnovationNotPositiveDefinite { observations: 1 })?;
        let nis = nu.dot(&chol.solve(&nu));
        if !(nis.is_finite() && nis <= self.gate) {
            return Ok(Some((nis, false)));
        }
        // K_L (3 x 4) and the landmark's rows of P H^T.
        let l_rows: [usize; 3] = core::array::from_fn(|k| li + k);
        let mut l_at = [0usize; 3];
        for (k, &i) in l_rows.iter().enumerate() {
            l_at[k] = row_of(i).ok_or(Error::UnknownLandmark { id })?;
        }
        let k_l: [Vector4<f64>; 3] =
            core::array::from_fn(|k| chol.solve(&Vector4::from(pht[l_at[k]])));
        // M = K_L (H P)_L, symmetric: what P_LL loses.
        let m = Matrix3::from_fn(|a, b| k_l[a].dot(&Vector4::from(pht[l_at[b]])));
        let before: [f64; 3] = core::array::from_fn(|k| self.cov(l_rows[k], l_rows[k]));
        for (k, b) in before.iter().enumerate() {
            let after = b - m[(k, k)];
            if !(after.is_finite() && after > 0.0) {
                return Err(Error::VarianceNotPositive {
                    index: l_rows[k],
                    before: *b,
                    after,
                });
            }
        }
        let dx: [f64; 3] = core::array::from_fn(|k| k_l[k].dot(&nu));
        if let Some(l) = self.local.as_deref_mut() {
            let (na, na0) = (l.n_active(), l.n_a0);
            // phi^T H^T (n_A0 x 4): the passive share of P H^T.
            let mut q = alloc::vec![[0.0f64; 4]; na0];
            for (t, &c) in cols.iter().enumerate() {
                let Some(&Place::Active(kc)) = l.place.get(c) else {
                    continue;
                };
                if let Some(col) = l.phit.get(kc * na0..(kc + 1) * na0) {
                    for (u, f) in col.iter().enumerate() {
                        for (rr, out) in q[u].iter_mut().enumerate() {
                            *out += f * o.h[rr][t];
                        }
                    }
                }
            }
            // P -= C G^T with C = [e_L, W], G = [W - e_L M, e_L], W = P H^T K_L^T.
            let d = 6;
            let mut c_a = alloc::vec![0.0; na * d];
            let mut g_a = alloc::vec![0.0; na * d];
            let mut u = alloc::vec![0.0; na0 * d];
            let mut v = alloc::vec![0.0; na0 * d];
            for k in 0..3 {
                for a in 0..na {
                    let w = k_l[k].dot(&Vector4::from(pht[a]));
                    c_a[(3 + k) * na + a] = w;
                    g_a[k * na + a] = w;
                }
                c_a[k * na + l_at[k]] = 1.0;
                g_a[(3 + k) * na + l_at[k]] = 1.0;
                for (mm, &at) in l_at.iter().enumerate() {
                    g_a[k * na + at] -= m[(mm, k)];
                }
                for uu in 0..na0 {
                    let w = k_l[k].dot(&Vector4::from(q[uu]));
                    u[(3 + k) * na0 + uu] = w;
                    v[k * na0 + uu] = w;
                }
            }
            l.commit(&c_a, &g_a, &u, &v, d);
        } else {
            // The landmark's new rows, from the old P (rows `rows` = every state).
            let new_rows: [Vec<f64>; 3] = core::array::from_fn(|k| {
                (0..n)
                    .map(|j| {
                        let hp = Vector4::from(pht[j]);
                        self.cov(l_rows[k], j) - k_l[k].dot(&hp)
                    })
                    .collect()
            });
            for (k, row) in new_rows.iter().enumerate() {
                let i = l_rows[k];
                for (j, &val) in row.iter().enumerate() {
                    let (a, b) = if i >= j { (i, j) } else { (j, i) };
                    self.p[(a, b)] = val;
                }
            }
        }
        for (k, &i) in l_rows.iter().enumerate() {
            self.x[i] += dx[k];
        }
        Ok(Some((nis, true)))
    }

    fn update_within(
        &mut self,
        batch: &[(LandmarkId, Measurement)],
    ) -> Result<UpdateReport, Error> {
        let slots = self.batch_slots(batch)?;
        self.prepare_local(&slots);
        // With `Settings::follow_points`, each observation linearised at its landmark's
        // estimate, the covariance moved with it (other updates and the smoother move
        // landmarks they do not observe).
        if self.settings.follow_points && !self.pose_lost() {
            for &s in &slots {
                self.follow_estimate(s);
            }
        }
        let camera = self.camera();
        let pose = self.pose();
        // Linearise every observation at the current estimate; one that cannot be projected
        // is rejected outright.
        let mut obs: Vec<Obs> = Vec::with_capacity(batch.len());
        let mut nis: Vec<f64> = alloc::vec![f64::INFINITY; batch.len()];
        let mut projected: Vec<usize> = Vec::with_capacity(batch.len());
        // An update that will be iterated is Gauss-Newton on the measurement model from its
        // first pass on, its heading's column constrained (`observation_model_constrained`).
        // Only a batch with a settled landmark is iterated: new landmarks were placed from
        // this pose, their projections are as linear in it as the pixels can tell, and
        // iterated alone they only drifted the heading (hall 11 out of its dark stretch:
        // 2.3 to 1.9 degrees of sigma and 2.2 degrees of turn from two new lamps).
        let iterating = self.pose_uncertain_for_linear_update()
            && slots
                .iter()
                .any(|&s| self.landmarks.get(s).is_some_and(|l| l.settled));
        for (b, (&s, (_, z))) in slots.iter().zip(batch).enumerate() {
            let model = if iterating {
                self.observation_model_constrained(s, &camera, &pose, &pose)
            } else {
                self.observation_model_with(s, &camera, &pose, true)
            };
            if let Ok((predicted, mut o)) = model {
                // Eq. (6)'s innovation, nu = z - h(x).
                let nu = z - predicted;
                o.nu = [nu[0], nu[1], nu[2], nu[3]];
                o.r = self.measurement_variances(&predicted);
                obs.push(o);
                projected.push(b);
            }
        }
        // With the pose this uncertain (a loop closed after a long dark stretch) the
        // projection is not linear over the prior's spread: the prior is kept for the
        // iterated update below.
        let mut ws = core::mem::take(&mut self.workspace);
        let prior = iterating.then(|| self.clone());
        let scale_point = self.scale_point();
        let mut result = self.gate_and_update(&obs, &projected, &mut nis, &mut ws);
        if result.is_ok()
            && let Some(prior) = prior
        {
            result = self.iterate_update(prior, &slots, batch, &obs, &projected, &nis, &mut ws);
        }
        self.workspace = ws;
        if result.is_ok()
            && let Some(from) = scale_point
        {
            self.follow_scale(&from);
        }
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
            self.record_gated(&mut report, s, Gated { id: *id, nis: v }, accepted);
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

    /// Updates with landmarks seen as points relative to the vehicle (not as pixels): each
    /// `position` is the landmark in the vehicle's frame now (x ahead, y left, z the height in
    /// the world), with its covariance. This is how lamps held out of the map while the pose
    /// was lost (triangulated over several frames in the dead-reckoned world, then carried to
    /// the vehicle's frame now) close a loop once their constellation names the landmarks they
    /// are: `h(x) = R(theta)^T (L - p)` for the horizontal part, `L_z` for the height.
    ///
    /// The update is iterated (Gauss-Newton on the prior and the observations, as on a lost
    /// pose), its first linearisation at `guess` (where the constellation puts the vehicle;
    /// the prior's mean and covariance are unchanged, so the result is the maximum a
    /// posteriori estimate of the prior and these observations). Observations outside the
    /// gate of the first pass are left out of every pass. On an error nothing changes.
    pub fn update_relative(
        &mut self,
        batch: &[RelativeObservation],
        guess: Pose2,
    ) -> Result<UpdateReport, Error> {
        if let Some(&value) = [guess.x, guess.y, guess.theta]
            .iter()
            .find(|v| !v.is_finite())
        {
            return Err(Error::NonFinite {
                what: "pose to linearise a relative update at",
                value,
            });
        }
        let mut slots: Vec<usize> = Vec::with_capacity(batch.len());
        let mut whiten: Vec<Matrix3<f64>> = Vec::with_capacity(batch.len());
        for o in batch {
            if let Some(&value) = o
                .position
                .iter()
                .chain(o.covariance.iter())
                .find(|v| !v.is_finite())
            {
                return Err(Error::NonFinite {
                    what: "relative observation of a landmark",
                    value,
                });
            }
            let s = self.slot(o.id).ok_or(Error::UnknownLandmark { id: o.id })?;
            if slots.contains(&s) {
                return Err(Error::DuplicateObservation { id: o.id });
            }
            slots.push(s);
            // `W = L^-1` with `covariance = L L^T`: the whitened rows have unit variance.
            let l = o
                .covariance
                .cholesky()
                .ok_or(Error::InnovationNotPositiveDefinite {
                    observations: batch.len(),
                })?
                .l();
            let w = l
                .try_inverse()
                .ok_or(Error::InnovationNotPositiveDefinite {
                    observations: batch.len(),
                })?;
            whiten.push(w);
        }
        self.prepare_local(&slots);
        let mut ws = core::mem::take(&mut self.workspace);
        let prior = self.clone();
        let health = self.health.clone();
        let mut at = self.x.clone();
        at[0] = guess.x;
        at[1] = guess.y;
        at[2] = guess.theta;
        let order: Vec<usize> = (0..batch.len()).collect();
        let mut nis: Vec<f64> = alloc::vec![f64::INFINITY; batch.len()];
        let mut kept: Vec<usize> = order.clone();
        let mut result = Ok(());
        for pass in 0..ITERATE_MAX_PASSES {
            let obs: Vec<Obs> = kept
                .iter()
                .filter_map(|&b| {
                    let (o, &s, w) = (batch.get(b)?, slots.get(b)?, whiten.get(b)?);
                    Some(relative_obs(&at, &prior.x, StateLayout::landmark(s), o, w))
                })
                .collect();
            let mut candidate = prior.clone();
            let mut pass_nis = alloc::vec![f64::INFINITY; obs.len()];
            let pass_order: Vec<usize> = (0..obs.len()).collect();
            if let Err(e) = candidate.gate_and_update(&obs, &pass_order, &mut pass_nis, &mut ws) {
                if pass == 0 {
                    result = Err(e);
                }
                break;
            }
            if pass == 0 {
                // The first pass's gate decides which observations take part.
                for (&b, &v) in kept.iter().zip(&pass_nis) {
                    if let Some(slot) = nis.get_mut(b) {
                        *slot = v;
                    }
                }
                let accepted: Vec<usize> = kept
                    .iter()
                    .copied()
                    .filter(|&b| nis.get(b).is_some_and(|&v| v <= self.gate))
                    .collect();
                if accepted.len() != kept.len() {
                    // Applied again without the rejected ones (their gate was the prior's).
                    kept = accepted;
                    if kept.is_empty() {
                        break;
                    }
                    continue;
                }
            }
            let step = candidate
                .x
                .iter()
                .zip(at.iter())
                .enumerate()
                .map(|(i, (a, b))| if i == 2 { wrap_angle(a - b) } else { a - b })
                .fold(0.0f64, |m, d| m.max(d.abs()));
            at = candidate.x.clone();
            *self = candidate;
            if step < RELATIVE_STEP_TOLERANCE {
                break;
            }
        }
        self.workspace = ws;
        self.health = health;
        if let Err(e) = result {
            let ws = core::mem::take(&mut self.workspace);
            *self = prior;
            self.workspace = ws;
            self.health.refused_updates += 1;
            return Err(e);
        }
        let mut report = UpdateReport::default();
        if !kept.is_empty() {
            self.health.updates += 1;
            self.health.iterated_updates += 1;
        }
        for (b, o) in batch.iter().enumerate() {
            let v = nis.get(b).copied().unwrap_or(f64::INFINITY);
            let gated = Gated { id: o.id, nis: v };
            if kept.contains(&b) {
                report.accepted.push(gated);
            } else {
                report.rejected.push(gated);
            }
        }
        Ok(report)
    }

    /// The pose's prior spread makes a projection visibly non-linear: a position sigma
    /// above [`ITERATE_POSITION_SIGMA_M`] or a heading sigma above
    /// [`ITERATE_HEADING_SIGMA_RAD`] (at 5 m and 436 px, 0.1 m is a second-order term of
    /// 0.2 px). Below both (every frame of a drive that sees lamps) the update is the plain
    /// EKF's and costs nothing more.
    fn pose_uncertain_for_linear_update(&self) -> bool {
        let (vx, vy, vt) = (self.cov(0, 0), self.cov(1, 1), self.cov(2, 2));
        vx.max(vy) > ITERATE_POSITION_SIGMA_M * ITERATE_POSITION_SIGMA_M
            || vt > ITERATE_HEADING_SIGMA_RAD * ITERATE_HEADING_SIGMA_RAD
    }

    /// The iterated EKF update (Bell and Cathey 1993: Gauss-Newton on the prior and the
    /// measurements): while the accepted observations' residuals at the corrected state differ
    /// from what their linearisation predicted by more than [`ITERATE_TOLERANCE_SIGMAS`] of
    /// the pixel noise, the update is made again from `prior` with every observation
    /// linearised at the corrected state, `nu = z - h(x_i) - H_i (x_0 - x_i)`; the covariance
    /// is the last pass's. At most [`ITERATE_MAX_PASSES`] passes; a pass that would gate out an
    /// observation the first one accepted, or fails, or moves the pose more than the pass
    /// before it did, leaves the last good pass in place. On a
    /// loop closed after 100 m of dead reckoning the single linear update left the pose
    /// 0.5 m and 3 degrees off with a 0.08 m sigma (docs/halls.md, "Loops").
    #[allow(clippy::too_many_arguments)]
    fn iterate_update(
        &mut self,
        prior: Ekf,
        slots: &[usize],
        batch: &[(LandmarkId, Measurement)],
        obs: &[Obs],
        projected: &[usize],
        nis: &[f64],
        ws: &mut Workspace,
    ) -> Result<(), Error> {
        // The accepted observations: (index in obs, index in the batch).
        let accepted: Vec<(usize, usize)> = projected
            .iter()
            .enumerate()
            .filter(|&(_, &b)| nis.get(b).is_some_and(|&v| v <= self.gate))
            .map(|(j, &b)| (j, b))
            .collect();
        if accepted.is_empty() {
            return Ok(());
        }
        let mut linearised: Vec<Obs> = accepted
            .iter()
            .filter_map(|&(j, _)| obs.get(j).copied())
            .collect();
        // Each pass relinearised at the estimate (the heading's column constrained): the
        // iterated update is Gauss-Newton on the measurement model of the settled landmarks;
        // a landmark not settled keeps its first pass's linearisation.
        let mut last_step = pose_step(&prior.x, &self.x);
        for _ in 1..ITERATE_MAX_PASSES {
            // The residuals at the corrected state against the linear model's.
            let camera = self.camera();
            let pose = self.pose();
            let mut worst = 0.0f64;
            let mut next: Vec<Obs> = Vec::with_capacity(accepted.len());
            for (o, &(_, b)) in linearised.iter().zip(&accepted) {
                let (Some(&s), Some((_, z))) = (slots.get(b), batch.get(b)) else {
                    return Ok(());
                };
                if self.landmarks.get(s).is_some_and(|l| !l.settled) {
                    next.push(*o);
                    continue;
                }
                // The heading's column at the pose before the update, where the covariance
                // has it (`Settings::first_estimate_pose`).
                let anchor = if self.settings.first_estimate_pose {
                    prior.pose()
                } else {
                    pose
                };
                let Ok((predicted, mut at)) =
                    self.observation_model_constrained(s, &camera, &pose, &anchor)
                else {
                    return Ok(());
                };
                // The linear model's residual here: `nu - H (x - x_0)` (its `nu` is taken back
                // to the prior's state).
                let step = state_step(&self.x, &prior.x, o);
                for r in 0..4 {
                    let linear = o.nu[r] - step[r];
                    let actual = z[r] - predicted[r];
                    let e = actual - linear;
                    // In squared sigmas (no square root without std).
                    worst = worst.max(e * e / o.r[r].max(f64::MIN_POSITIVE));
                }
                // Linearised here, its innovation taken back to the prior's state.
                let back = state_step(&prior.x, &self.x, &at);
                at.nu = core::array::from_fn(|r| z[r] - predicted[r] - back[r]);
                at.r = self.measurement_variances(&predicted);
                next.push(at);
            }
            if worst <= ITERATE_TOLERANCE_SIGMAS * ITERATE_TOLERANCE_SIGMAS {
                break;
            }
            let mut candidate = prior.clone();
            let mut pass_nis = alloc::vec![f64::INFINITY; next.len()];
            let order: Vec<usize> = (0..next.len()).collect();
            if candidate
                .gate_and_update(&next, &order, &mut pass_nis, ws)
                .is_err()
                || pass_nis.iter().any(|&v| v.is_nan() || v > candidate.gate)
            {
                break;
            }
            // Gauss-Newton converges with steps that shrink. A pass whose pose step grows
            // walks along a direction the columns (the heading's constrained, the others the
            // derivative) and the model disagree on: in hall 27's U-turn 0.04, 0.06, 0.08 ...
            // m a pass, the pose and its two lamps together 0.6 m off in one frame, the map's
            // shared translation 3.6 sigma. The last pass before it stays. (Requiring the
            // steps to halve lost the fisheye hall 17's loop, whose passes converge slowly.)
            let step = pose_step(&self.x, &candidate.x);
            if step > last_step {
                break;
            }
            last_step = step;
            linearised = next;
            let health = self.health.clone();
            *self = candidate;
            self.health = health;
            self.health.iterated_updates += 1;
        }
        Ok(())
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
        if self.local.is_some() {
            if let Some(local_obs) = self.local_observations(obs) {
                return self.local_gate_and_update(&local_obs, projected, nis, ws);
            }
            self.settle();
        }
        innovation_products(self.p.as_slice(), n, obs, ws);
        let Some(keep) = self.gate_batch(obs, projected, nis, n, ws)? else {
            return Ok(());
        };
        let d = 4 * keep.len();
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

    /// The batch's gate: each observation's NIS with its own 4x4 block of `S` (`A` and `S`
    /// in the workspace, `n` rows), into `nis[projected[j]]`; `A` and `S` compacted to the
    /// accepted ones, which are returned (`None`: none accepted).
    fn gate_batch(
        &self,
        obs: &[Obs],
        projected: &[usize],
        nis: &mut [f64],
        n: usize,
        ws: &mut Workspace,
    ) -> Result<Option<Vec<usize>>, Error> {
        let d = 4 * obs.len();
        if ws.s.iter().any(|v| !v.is_finite()) {
            return Err(Error::InnovationNotPositiveDefinite {
                observations: obs.len(),
            });
        }
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
            return Ok(None);
        }
        if keep.len() < obs.len() {
            compact(n, d, &keep, &mut ws.a, &mut ws.s);
        }
        Ok(Some(keep))
    }

    /// The observations with their columns in the local session's active rows, `None` when
    /// one involves a passive state.
    fn local_observations(&self, obs: &[Obs]) -> Option<Vec<Obs>> {
        let l = self.local.as_ref()?;
        obs.iter()
            .map(|o| {
                let mut lo = *o;
                for c in lo.cols.iter_mut().take(lo.q) {
                    match l.place.get(*c) {
                        Some(&Place::Active(k)) => *c = k,
                        _ => return None,
                    }
                }
                Some(lo)
            })
            .collect()
    }

    /// [`Self::gate_and_update`] in the open local session (`crate::local`), `obs` in its
    /// active rows.
    fn local_gate_and_update(
        &mut self,
        obs: &[Obs],
        projected: &[usize],
        nis: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), Error> {
        let Some(l) = self.local.as_deref() else {
            return Ok(());
        };
        let (na, na0) = (l.n_active(), l.n_a0);
        innovation_products(l.paa.as_slice(), na, obs, ws);
        let Some(keep) = self.gate_batch(obs, projected, nis, na, ws)? else {
            return Ok(());
        };
        // phi^T H_A^T (n_A0 x d): the passive rows' share of P H^T is P0_BA0 times it.
        let d = 4 * keep.len();
        let mut a_bot = alloc::vec![0.0; na0 * d];
        let kept = keep.iter().filter_map(|&j| obs.get(j));
        for (o, cols4) in kept.clone().zip(a_bot.chunks_exact_mut(4 * na0)) {
            for (r, col) in cols4.chunks_exact_mut(na0).enumerate() {
                for (t, &k) in o.cols.iter().enumerate().take(o.q) {
                    let h = o.h[r][t];
                    if h == 0.0 {
                        continue;
                    }
                    if let Some(f) = l.phit.get(k * na0..(k + 1) * na0) {
                        for (v, &fv) in col.iter_mut().zip(f) {
                            *v += h * fv;
                        }
                    }
                }
            }
        }
        let nu: Vec<f64> = kept.flat_map(|o| o.nu).collect();
        let error = Error::InnovationNotPositiveDefinite {
            observations: keep.len(),
        };
        self.local_correct(ws, &a_bot, &nu, d, error, true)
    }

    /// The factored update `P - W W^T`, `x + W L^-1 nu` in the open local session, from `A`'s
    /// active rows (`P_AA H^T`, in `ws.a`), `phi^T H_A^T` (`a_bot`) and `S` (`d x d`, in
    /// `ws.s`): `P_AA` and `x_A` as the dense filter, `phi` and `psi` as the module docs say,
    /// the passive states through `P0_BA0`. With `check`, every active variance must stay
    /// positive (a merge's constraint all but zeroes the dropped landmark's on purpose).
    pub(crate) fn local_correct(
        &mut self,
        ws: &mut Workspace,
        a_bot: &[f64],
        nu: &[f64],
        d: usize,
        not_positive: Error,
        check: bool,
    ) -> Result<(), Error> {
        let Some(l) = self.local.as_deref() else {
            return Ok(());
        };
        let (na, na0, n0) = (l.n_active(), l.n_a0, l.n0);
        let ne = na + na0;
        // A over the active rows and the rows of phi^T stacked: W and dx come out stacked.
        let mut a_ext = alloc::vec![0.0; ne * d];
        for (c, dst) in a_ext.chunks_exact_mut(ne).enumerate() {
            let (top, bottom) = dst.split_at_mut(na);
            if let (Some(t), Some(b)) = (
                ws.a.get(c * na..(c + 1) * na),
                a_bot.get(c * na0..(c + 1) * na0),
            ) {
                top.copy_from_slice(t);
                bottom.copy_from_slice(b);
            }
        }
        let chol =
            nalgebra::Cholesky::new(DMatrix::from_column_slice(d, d, &ws.s)).ok_or(not_positive)?;
        gain_factors(
            ne,
            d,
            chol.l_dirty().as_slice(),
            &ws.s,
            nu,
            false,
            &a_ext,
            &mut ws.w,
            &mut ws.y,
            &mut ws.dx,
            &mut ws.lhs,
            &mut ws.rhs,
        );
        let mut w_top = alloc::vec![0.0; na * d];
        let mut w_bot = alloc::vec![0.0; na0 * d];
        for ((w, t), b) in
            ws.w.chunks_exact(ne)
                .zip(w_top.chunks_exact_mut(na))
                .zip(w_bot.chunks_exact_mut(na0))
        {
            t.copy_from_slice(&w[..na]);
            b.copy_from_slice(&w[na..]);
        }
        if check {
            diagonal_change(na, &w_top, &w_top, -1.0, &mut ws.y);
            check_variances(l.paa.as_slice(), na, &ws.y).map_err(|e| match e {
                Error::VarianceNotPositive {
                    index,
                    before,
                    after,
                } => Error::VarianceNotPositive {
                    index: l.active.get(index).copied().unwrap_or(index),
                    before,
                    after,
                },
                e => e,
            })?;
        }
        // The passive states' correction P0_BA0 (phi^T H^T L^-T L^-1 nu).
        let mut dx_b = alloc::vec![0.0; n0];
        crate::linalg::gemm(&mut dx_b, n0, 1, &l.g0, &ws.dx[na..], na0, 1.0, false);
        let dx = l.scatter(ws.dx.get(..na).unwrap_or(&[]), &dx_b);
        check_state(&self.x, &dx)?;
        // Commit.
        if let Some(l) = self.local.as_deref_mut() {
            l.commit(&w_top, &w_top, &w_bot, &w_bot, d);
        }
        correct_state(&mut self.x, &dx);
        Ok(())
    }

    /// [`Ekf::merge_landmarks`]'s constraint `x_a - x_b = 0` (state indices `ia`, `ib`, the
    /// difference `d`, the constraint's variance `noise` on each axis) in the open local
    /// session; `false` (nothing done) when either is passive.
    pub(crate) fn local_merge(
        &mut self,
        ia: usize,
        ib: usize,
        d: &Vector3<f64>,
        noise: f64,
    ) -> Result<bool, Error> {
        let Some(l) = self.local.as_deref() else {
            return Ok(false);
        };
        let (Some(&Place::Active(ka)), Some(&Place::Active(kb))) =
            (l.place.get(ia), l.place.get(ib))
        else {
            return Ok(false);
        };
        let (na, na0) = (l.n_active(), l.n_a0);
        let mut ws = core::mem::take(&mut self.workspace);
        // A = P_AA H^T with H = [.. I .. -I ..], S = H A, and phi^T H^T.
        let cols: Vec<usize> = (ka..ka + 3).chain(kb..kb + 3).collect();
        let mut g = alloc::vec![0.0; na * 6];
        gather_columns(l.paa.as_slice(), na, &cols, &mut g);
        ws.a.clear();
        ws.a.resize(na * 3, 0.0);
        for (c, a) in ws.a.chunks_exact_mut(na).enumerate() {
            for (i, v) in a.iter_mut().enumerate() {
                *v = g[c * na + i] - g[(c + 3) * na + i];
            }
        }
        ws.s.clear();
        ws.s.resize(9, 0.0);
        for c in 0..3 {
            for r in 0..3 {
                ws.s[c * 3 + r] = ws.a[c * na + ka + r] - ws.a[c * na + kb + r];
            }
        }
        for c in 0..3 {
            for r in 0..c {
                let v = 0.5 * (ws.s[c * 3 + r] + ws.s[r * 3 + c]);
                ws.s[c * 3 + r] = v;
                ws.s[r * 3 + c] = v;
            }
            ws.s[c * 3 + c] += noise;
        }
        let mut a_bot = alloc::vec![0.0; na0 * 3];
        for (c, col) in a_bot.chunks_exact_mut(na0).enumerate() {
            for (t, v) in col.iter_mut().enumerate() {
                *v = l.phit[(ka + c) * na0 + t] - l.phit[(kb + c) * na0 + t];
            }
        }
        let nu = [-d[0], -d[1], -d[2]];
        let error = Error::NonFinite {
            what: "merge constraint covariance",
            value: f64::NAN,
        };
        let result = self.local_correct(&mut ws, &a_bot, &nu, 3, error, false);
        self.workspace = ws;
        result.map(|()| true)
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
        self.innovation_covariance_with(m, false)
    }

    /// [`Self::innovation_covariance`], or with `upper` an upper bound of it (in the
    /// positive semi-definite order) that costs less while a local session is open: a
    /// passive landmark's own block read as the session found it (`P_bb` only shrinks).
    pub(crate) fn innovation_covariance_with(&self, m: &Obs, upper: bool) -> Matrix4<f64> {
        let q = m.q.min(MAX_INVOLVED);
        // The landmark's own block (columns 3..6 of an observation) read at once: a passive
        // one's entries share their products.
        let li = m.cols.get(POSE_DIM).copied().unwrap_or(0);
        let block = match (&self.local, upper) {
            (Some(l), true) => l.block3_upper(self.p.as_slice(), li),
            _ => self.block3(li),
        };
        let in_block = |c: usize| (li..li + LANDMARK_DIM).contains(&c);
        // The involved block of P.
        let mut pq = [[0.0; MAX_INVOLVED]; MAX_INVOLVED];
        for (a, &ca) in m.cols.iter().enumerate().take(q) {
            for (b, &cb) in m.cols.iter().enumerate().take(a + 1) {
                let v = if in_block(ca) && in_block(cb) {
                    block[(ca - li, cb - li)]
                } else {
                    self.cov_with(ca, cb, upper)
                };
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

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod landmark_only_tests {
    use super::*;

    /// The landmark-only update is the Schmidt update: `K = [0; K_L; 0]`, `K_L = (P H^T)_L
    /// S^-1`, `x += K nu`, `P = (I - K H) P (I - K H)^T + K R K^T`, against the dense
    /// formulas by nalgebra, with the filter dense and in a local session; only the
    /// landmark's state, rows and columns change.
    #[test]
    fn a_landmark_only_update_is_the_schmidt_update_dense_and_in_a_session() {
        for margin in [0.0, 1.0] {
            let mut ekf = crate::local::tests::drive(margin);
            let (id, z0) = ekf.visible_landmarks()[0];
            let s = ekf.slot(id).unwrap();
            if margin > 0.0 {
                ekf.prepare_local(&[s]);
                assert!(ekf.local.is_some(), "no session open");
            }
            let z = z0 + Vector4::new(0.4, -0.3, 0.2, 0.1);
            let n = ekf.state_len();
            let x = ekf.state().clone();
            // `covariance` reads a session through a settled copy.
            let p = ekf.covariance();
            let (zhat, h) = ekf.update_jacobian(id).unwrap();
            let r =
                DMatrix::from_diagonal(&DVector::from_row_slice(&ekf.measurement_variances(&zhat)));
            let s_mat = &h * &p * h.transpose() + &r;
            let li = ekf.landmark_state_index(id).unwrap();
            let pht = &p * h.transpose();
            let k_l = pht.rows(li, 3) * s_mat.clone().try_inverse().unwrap();
            let mut k = DMatrix::zeros(n, 4);
            k.rows_mut(li, 3).copy_from(&k_l);
            let nu = DVector::from_row_slice((z - zhat).as_slice());
            let x_want = &x + &k * &nu;
            let a = DMatrix::identity(n, n) - &k * &h;
            let p_want = &a * &p * a.transpose() + &k * &r * k.transpose();
            let (nis, accepted) = ekf.landmark_only_update(s, &z).unwrap().unwrap();
            assert!(accepted, "margin {margin}: NIS {nis}");
            let nis_want = nu.dot(&(s_mat.try_inverse().unwrap() * &nu));
            assert!((nis - nis_want).abs() < 1e-9 * nis_want.max(1.0));
            let dx = (ekf.state() - &x_want).amax();
            assert!(dx < 1e-10, "margin {margin}: state off by {dx}");
            let got = ekf.covariance();
            let dp = (&got - &p_want).amax() / p.amax();
            assert!(
                dp < 1e-9,
                "margin {margin}: covariance off by {dp} (relative)"
            );
            // Nothing but the landmark's rows and columns moved.
            let scale = p.amax();
            for i in 0..n {
                for j in 0..n {
                    if !(li..li + 3).contains(&i) && !(li..li + 3).contains(&j) {
                        assert!((got[(i, j)] - p[(i, j)]).abs() <= 1e-12 * scale);
                    }
                }
            }
        }
    }

    /// Outside the gate nothing changes.
    #[test]
    fn a_landmark_only_update_outside_the_gate_changes_nothing() {
        let mut ekf = crate::local::tests::drive(0.0);
        let (id, z0) = ekf.visible_landmarks()[0];
        let s = ekf.slot(id).unwrap();
        let before = ekf.clone();
        let (nis, accepted) = ekf
            .landmark_only_update(s, &(z0 + Vector4::new(60.0, 0.0, 60.0, 0.0)))
            .unwrap()
            .unwrap();
        assert!(!accepted && nis > ekf.gate_bound(), "{nis}");
        assert_eq!(ekf.state(), before.state());
        assert_eq!(ekf.covariance(), before.covariance());
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod linearisation_point_tests {
    use super::*;
    use crate::Settings;
    use crate::landmarks::Placement;

    /// Moving a landmark's linearisation point by `d` is `P <- T P T^T` with `T = I + (J d)
    /// e_theta^T + sum_c (g_c(new) - g_c) e_c^T` on the landmark's rows, against the dense
    /// product by nalgebra, with the filter dense and in a local session. Without a
    /// placement (`follow_points` off) the baseline's column moves by `d / B` and no other;
    /// with `follow_points` (the default), each estimated camera parameter's by its placement's column at the
    /// new point less the one held, the columns written out here from the geometry: the
    /// baseline's `(L - C) / B` and the focal length's `R (0, 0, z / f)`, `C` and `R` the
    /// camera's position and rotation at the placing pose, `z` the point's depth in it.
    #[test]
    fn moving_a_linearisation_point_shears_the_covariance_dense_and_in_a_session() {
        for follow_points in [false, true] {
            for margin in [0.0, 1.0] {
                let mut ekf = crate::local::tests::drive_with(Settings {
                    local_margin_m: margin,
                    follow_points,
                    ..Settings::default()
                });
                let (id, _) = ekf.visible_landmarks()[0];
                let s = ekf.slot(id).unwrap();
                if margin > 0.0 {
                    ekf.prepare_local(&[s]);
                    assert!(ekf.local.is_some(), "no session open");
                }
                let p = ekf.covariance();
                let n = p.nrows();
                let d = Vector3::new(0.3, -0.2, 0.4);
                let li = ekf.landmark_state_index(id).unwrap();
                let kb = ekf.camera_state_index(Param::Baseline).unwrap();
                let kf = ekf.camera_state_index(Param::F).unwrap();
                let c = ekf.camera();
                let mut t = DMatrix::<f64>::identity(n, n);
                t[(li, 2)] = -d.y;
                t[(li + 1, 2)] = d.x;
                let slot = ekf.landmarks[s];
                assert_eq!(slot.placement.is_some(), follow_points);
                match slot.placement {
                    None => {
                        for a in 0..3 {
                            t[(li + a, kb)] = d[a] / c.baseline;
                        }
                    }
                    Some(held) => {
                        let at = slot.first.unwrap() + d;
                        let rot = held.pose.world_from_robot_rotation()
                            * c.mount.robot_from_rig_rotation();
                        let rig_point = rig_model::rig::point_in_rig(&c, &held.pose, &at);
                        let camera = at - rot * rig_point;
                        let gb = (at - camera) / c.baseline;
                        let gf = rot * Vector3::new(0.0, 0.0, rig_point.z / c.f);
                        for a in 0..3 {
                            t[(li + a, kb)] = gb[a] - held.columns[(a, Param::Baseline.index())];
                            t[(li + a, kf)] = gf[a] - held.columns[(a, Param::F.index())];
                        }
                        assert!(
                            (gf - held.columns.column(Param::F.index())).norm() > 1e-6,
                            "the move changed no focal-length column"
                        );
                    }
                }
                let want = &t * &p * t.transpose();
                assert!(
                    ekf.shear_linearisation_point(s, &d),
                    "margin {margin}, follow_points {follow_points}"
                );
                let got = ekf.covariance();
                let off = (&got - &want).amax() / p.amax();
                assert!(
                    off < 1e-9,
                    "margin {margin}, follow_points {follow_points}: covariance off by {off} (relative)"
                );
            }
        }
    }

    /// The focal length refined, and the landmark's depth with it, does not move the focal
    /// length's column of its placement: `z / f = B / d` stays. Taken as the point's move
    /// times the column's derivative, each refinement sheared it (the paper's square with its
    /// focal length 2.5 % off ended 6.9 sigma off).
    #[test]
    fn a_refined_focal_length_does_not_move_the_placement_s_column() {
        let mut ekf = crate::local::tests::drive_with(Settings {
            follow_points: true,
            ..Settings::default()
        });
        let (id, _) = ekf.visible_landmarks()[0];
        let s = ekf.slot(id).unwrap();
        let slot = ekf.landmarks[s];
        let (held, at) = (slot.placement.unwrap(), slot.first.unwrap());
        let before = Placement::at(&ekf.camera(), &held.pose, &at).unwrap();
        // The focal length 2 % larger, the point 2 % deeper along the placing camera's axis.
        let kf = ekf.camera_state_index(Param::F).unwrap();
        let c = ekf.camera();
        ekf.x[kf] = c.f * 1.02;
        let rot = held.pose.world_from_robot_rotation() * c.mount.robot_from_rig_rotation();
        let rig_point = rig_model::rig::point_in_rig(&c, &held.pose, &at);
        let deeper = at + rot * Vector3::new(0.0, 0.0, 0.02 * rig_point.z);
        let after = Placement::at(&ekf.camera(), &held.pose, &deeper).unwrap();
        let (gf0, gf1) = (
            before.columns.column(Param::F.index()),
            after.columns.column(Param::F.index()),
        );
        assert!((gf1 - gf0).norm() < 1e-9 * gf0.norm(), "{gf0:?} -> {gf1:?}");
    }

    /// A dark stretch, then lamps seen for the first time only: nothing the filter sees ties
    /// them to the map before the stretch, so its heading's sigma must not fall. With the
    /// points following the estimates and the covariance moved with them
    /// (`Settings::follow_points`) it does not (0.0119 -> 0.0128 rad); moved without it,
    /// 0.0119 -> 0.0021 rad. The old rule (`follow_points` off) moves them without it until a
    /// landmark is known to 0.5 m (docs/halls.md, "The linearisation point").
    #[test]
    fn lamps_seen_for_the_first_time_do_not_tell_the_filter_its_heading() {
        let rig = crate::filter::tests::rig_estimating(&[(Param::Baseline, 0.005)]);
        let settings = Settings {
            follow_points: true,
            ..Settings::default()
        };
        let mut ekf = Ekf::from_prior(&rig, settings).unwrap();
        let mut noise = crate::local::tests::Lcg(11);
        // Lamps 7 m above the cameras, in rows across the drive; none between x = 8 and
        // x = 20 m.
        let lamps: Vec<Vector3<f64>> = (0..200)
            .map(|k| Vector3::new(f64::from(k / 5), f64::from(k % 5) - 2.0, 7.8))
            .filter(|p| p.x < 8.0 || p.x > 20.0)
            .collect();
        let mut ids: Vec<Option<LandmarkId>> = alloc::vec![None; lamps.len()];
        let mut truth = Pose2::default();
        let (v, dt) = (0.5, 0.1);
        let mut sigma_at_dark_end = None;
        for _ in 0..800 {
            ekf.predict(v, 0.0, 0.0, dt).unwrap();
            truth = Pose2::new(truth.x + v * dt, 0.0, 0.0);
            if truth.x > 17.0 && sigma_at_dark_end.is_none() {
                sigma_at_dark_end = Some(ekf.cov(2, 2).sqrt());
            }
            let mut batch = Vec::new();
            for (p, id) in lamps.iter().zip(ids.iter_mut()) {
                if (p.x - truth.x).abs() > 3.0 {
                    continue;
                }
                let Ok(mut z) = rig_model::project(&rig.nominal, &truth, p) else {
                    continue;
                };
                for c in z.iter_mut() {
                    *c += noise.next();
                }
                match id {
                    Some(id) => batch.push((*id, z)),
                    None => *id = Some(ekf.add_landmark(&z).unwrap()),
                }
            }
            ekf.update(&batch).unwrap();
            if truth.x > 35.0 {
                break;
            }
        }
        let before = sigma_at_dark_end.unwrap();
        let after = ekf.cov(2, 2).sqrt();
        assert!(
            before > 1e-3,
            "the dark stretch left the heading known to {before} rad"
        );
        assert!(
            after >= 0.98 * before,
            "the heading's sigma fell from {before} to {after} rad on lamps seen for the first time"
        );
    }

    /// Three lamps mapped from a start pose of heading variance `heading_var`, then one
    /// prediction: the two tests of `Settings::first_estimate_prediction` below.
    fn predicted_once(first_estimate_prediction: bool, heading_var: f64) -> Ekf {
        let rig = crate::filter::tests::rig_estimating(&[(Param::Baseline, 0.005)]);
        let settings = Settings {
            first_estimate_prediction,
            ..Settings::default()
        };
        let mut ekf = Ekf::from_prior(&rig, settings).unwrap();
        let start = Pose2::new(20.0, 3.0, 0.3);
        ekf.set_start_pose(
            start,
            &Matrix3::from_diagonal(&Vector3::new(1e-4, 2e-4, heading_var)),
        )
        .unwrap();
        for &(x, y) in &[(19.0, 2.5), (21.0, 4.0), (22.5, 3.5)] {
            let z = rig_model::project(&rig.nominal, &start, &Vector3::new(x, y, 7.8)).unwrap();
            ekf.add_landmark(&z).unwrap();
        }
        ekf.predict(0.5, 0.0, 0.1, 0.05).unwrap();
        ekf
    }

    /// `Settings::first_estimate_prediction`: the prediction after an update moved the pose
    /// by `d` is the usual one after the covariance was sheared with the pose's linearisation
    /// point, `P <- T P T^T`, `T = I + (J d) e_theta^T` on the position's rows (the landmarks'
    /// shear of `follow_points`, for the pose), and it applies with the pose not lost.
    #[test]
    fn the_first_estimates_prediction_is_the_usual_one_after_the_pose_s_shear() {
        let (mut fej, mut usual) = (predicted_once(true, 1e-5), predicted_once(false, 1e-5));
        assert!(!fej.pose_lost());
        // An update's move of the pose, the covariance left as it was.
        let d = (0.15, -0.2);
        for ekf in [&mut fej, &mut usual] {
            ekf.x[0] += d.0;
            ekf.x[1] += d.1;
        }
        let n = usual.p.nrows();
        let mut t = DMatrix::<f64>::identity(n, n);
        (t[(0, 2)], t[(1, 2)]) = (-d.1, d.0);
        let sheared = &t * usual.covariance() * t.transpose();
        for r in 0..n {
            for c in 0..=r {
                usual.p[(r, c)] = sheared[(r, c)];
                usual.p[(c, r)] = sheared[(r, c)];
            }
        }
        fej.predict(0.5, 0.0, 0.1, 0.05).unwrap();
        usual.predict(0.5, 0.0, 0.1, 0.05).unwrap();
        let (a, b) = (fej.covariance(), usual.covariance());
        let scale = b.abs().max();
        assert!(
            (&a - &b).abs().max() <= 1e-12 * scale,
            "first-estimates prediction {a} against the sheared usual one {b}"
        );
        assert_eq!(fej.state(), usual.state());
    }

    /// Above its heading bound (`Settings::first_estimate_prediction_heading_sigma_rad`, 0.5
    /// degrees) the prediction takes the corrected pose: the same covariance as with the
    /// first estimates off, after an update's move of the pose; below it, not.
    #[test]
    fn the_first_estimates_prediction_stops_above_its_heading_bound() {
        let make = |first_estimate_prediction, heading_sigma_deg: f64| {
            let var = heading_sigma_deg.to_radians().powi(2);
            let mut ekf = predicted_once(first_estimate_prediction, var);
            ekf.x[0] += 0.15;
            ekf.x[1] -= 0.2;
            ekf.predict(0.5, 0.0, 0.1, 0.05).unwrap();
            ekf.covariance()
        };
        let differ = |sigma_deg| {
            let (on, off) = (make(true, sigma_deg), make(false, sigma_deg));
            (&on - &off).abs().max() / off.abs().max()
        };
        assert!(Settings::default().first_estimate_prediction);
        assert!(differ(0.3) > 1e-6, "no first estimates below the bound");
        assert!(differ(1.0) == 0.0, "first estimates above the bound");
    }

    /// While the pose is lost its updates move it by decimetres (hall 22 of `hall_mc 24 11
    /// --lens radtan --odometry-tau 0.6` after its hand-over: 2 to 18 cm a frame). The
    /// prediction that follows carries the pose's share of the world's unobservable turn from
    /// the pose before the update, where the covariance has it (the first-estimates Jacobian
    /// of Huang, Mourikis and Roumeliotis, ISER 2008): taken from the corrected pose instead,
    /// the turn's direction and the estimate part by the correction, and lamps the filter
    /// knows only relative to the vehicle told it the heading of the world (hall 22: 3.8 to
    /// 0.85 degrees of sigma in one frame with the heading 7.5 degrees off).
    #[test]
    fn a_corrected_pose_does_not_tell_the_filter_the_world_s_heading() {
        let rig = crate::filter::tests::rig_estimating(&[(Param::Baseline, 0.005)]);
        let settings = Settings {
            follow_points: true,
            first_estimate_pose: true,
            ..Settings::default()
        };
        let mut ekf = Ekf::from_prior(&rig, settings).unwrap();
        let start = Pose2::new(20.0, 0.0, 0.0);
        ekf.set_start_pose(start, &(Matrix3::identity() * 1e-8))
            .unwrap();
        let lamps = [
            (19.0, -1.5),
            (21.0, 1.0),
            (22.5, -0.5),
            (20.5, 2.0),
            (18.5, 1.2),
        ];
        let ids: Vec<LandmarkId> = lamps
            .iter()
            .map(|&(x, y)| {
                let z = rig_model::project(&rig.nominal, &start, &Vector3::new(x, y, 7.8)).unwrap();
                ekf.add_landmark(&z).unwrap()
            })
            .collect();
        ekf.predict(0.5, 0.0, 0.0, 0.05).unwrap();
        // The world's heading 4 degrees uncertain: a turn of everything about the origin,
        // `dp = J p`, `dtheta = 1`, `dL = J L` at the landmarks' linearisation points.
        let n = ekf.x.len();
        let mut turn = DVector::<f64>::zeros(n);
        (turn[0], turn[1], turn[2]) = (-ekf.x[1], ekf.x[0], 1.0);
        for (s, slot) in ekf.landmarks.iter().enumerate() {
            let at = slot.first.unwrap();
            let i = StateLayout::landmark(s);
            (turn[i], turn[i + 1]) = (-at.y, at.x);
        }
        let sigma = 0.07;
        ekf.p += &turn * turn.transpose() * (sigma * sigma);
        assert!(ekf.pose_lost());
        // An update corrected the pose by a quarter of a metre, the turn untouched.
        ekf.x[0] += 0.15;
        ekf.x[1] -= 0.2;
        ekf.predict(0.5, 0.0, 0.0, 0.05).unwrap();
        let before = ekf.cov(2, 2).sqrt();
        // The lamps where the filter predicts them: nothing new about the world's heading.
        let batch: Vec<(LandmarkId, Measurement)> = ids
            .iter()
            .map(|&id| (id, ekf.predict_measurement(id).unwrap().0))
            .collect();
        let report = ekf.update(&batch).unwrap();
        assert_eq!(report.accepted.len(), ids.len());
        let after = ekf.cov(2, 2).sqrt();
        assert!(
            after >= 0.95 * before,
            "the heading's sigma fell from {before} to {after} rad on lamps known only relative to the vehicle"
        );
    }
}
