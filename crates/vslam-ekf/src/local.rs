//! The local session: the update confined to the states near the vehicle, exactly (the
//! compressed filter of Guivant and Nebot, "Optimization of the simultaneous localization and
//! map-building algorithm for real-time implementation", IEEE T-RA 17(3), 2001).
//!
//! A frame's observations involve the pose, a few landmarks and the camera, yet the dense
//! update changes all of `P`: `n^2` per observation, three quarters of a large hall's replay
//! (docs/benchmarks.md, "A hall mapped once"). While the vehicle works in one place, the
//! states split into the active ones `A` (the pose, the camera, the landmarks within reach of
//! the view) and the passive rest `B`, and every prediction and update acts on `A` alone. With
//! `P0` the covariance when the session opened (`A0` its active states), the session keeps
//!
//! - `P_AA` exactly, as the filter would;
//! - `P_AB = phi P0_A0B`, with `phi` (`n_A x n_A0`) the product of the transforms the steps
//!   applied to the active rows (`phi = I` at the start; a prediction multiplies its pose rows
//!   by `F`, an update multiplies by `I - K_A H_A`, a new landmark adds the rows `G phi` of its
//!   initialisation Jacobian);
//! - `P_BB = P0_BB - P0_BA0 psi P0_A0B`, with `psi` (`n_A0 x n_A0`) the sum over the updates of
//!   `V^T V`, `V = L^-1 H_A phi`;
//! - the passive states themselves, exactly at every update: `x_B += P0_BA0 V^T L^-1 nu`.
//!
//! An update then costs `O((n_A + n_A0) n_A d)`, independent of the map's size. Any entry of
//! `P` can still be read exactly ([`Local::entry`]); when an observation involves a passive
//! landmark (the vehicle has moved on), the session is settled: `P_AB` and `P_BB` written out
//! from the formulas above, `O(n_B^2 n_A0)`, once per a few metres driven. The result is the
//! dense filter's to rounding (tests: `a_local_session_is_the_dense_filter`).
//!
//! [`Ekf`]'s code reads the covariance through [`Ekf::cov`], which knows both forms; the
//! steps that change it (`predict`, `update`, `add_landmark`, `remove_landmark`,
//! `merge_landmarks`) have their local branches next to the dense ones.

use alloc::vec::Vec;

use nalgebra::{DMatrix, Matrix3};

use crate::filter::Ekf;
use crate::kernels::gather_columns;
use crate::linalg::{rank_update_lower, sym};
use crate::state::{LANDMARK_DIM, POSE_DIM, StateLayout};

/// Smallest state for which updates open a local session: below it the dense update costs
/// less than the session's (whose active block alone is about 150 states in a hall). Above it
/// [`crate::CovarianceUpdate::Auto`] takes the factored form, the session's, where the dense
/// filter would take the Joseph form up to [`crate::AUTO_JOSEPH_MAX_STATES`].
pub const LOCAL_MIN_STATES: usize = 250;

/// Where a state's covariance lives during a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Place {
    /// Row `k` of `P_AA`.
    Active(usize),
    /// Row `b` of `P0` (the covariance buffer as the session found it).
    Passive(usize),
}

/// An open session (see the module docs). `P0` is the filter's covariance buffer itself,
/// untouched while the session is open.
#[derive(Debug, Clone)]
pub(crate) struct Local {
    /// For each state index, where its covariance lives.
    pub(crate) place: Vec<Place>,
    /// The state index of each row of `P_AA`, increasing.
    pub(crate) active: Vec<usize>,
    /// `P_AA`, lower triangle.
    pub(crate) paa: DMatrix<f64>,
    /// `phi^T`, `n_A0 x n_A`, column-major: column `k` is row `k` of `phi`.
    pub(crate) phit: Vec<f64>,
    /// `psi`, `n_A0 x n_A0`, lower triangle.
    pub(crate) psi: Vec<f64>,
    /// `P0`'s columns of the states active at the start, `n_0 x n_A0` (`n_0` the state's
    /// length then).
    pub(crate) g0: Vec<f64>,
    /// `n_A0`.
    pub(crate) n_a0: usize,
    /// `n_0`, the rows of `P0`.
    pub(crate) n0: usize,
}

impl Local {
    /// Rows of `P_AA`.
    pub(crate) fn n_active(&self) -> usize {
        self.active.len()
    }

    /// A correction of the whole state in state order, from its active rows' part `dx_a`
    /// (length `n_A`) and the passive rows' `dx_b` (rows of `P0`).
    pub(crate) fn scatter(&self, dx_a: &[f64], dx_b: &[f64]) -> Vec<f64> {
        self.place
            .iter()
            .map(|place| match *place {
                Place::Active(k) => dx_a.get(k).copied().unwrap_or(f64::NAN),
                Place::Passive(b) => dx_b.get(b).copied().unwrap_or(f64::NAN),
            })
            .collect()
    }

    /// Commits a rank-`d` change of the covariance `P -= C G^T` whose active rows are
    /// `C_A = x` with `G_A = y`, and whose `phi`-rows are `u` (`P_BA`'s share) with `v`
    /// (`n_A0 x d` each, column-major): `P_AA -= x y^T`, `phi^T -= u y^T`, `psi += u v^T`
    /// (module docs). A Kalman update's `W W^T` is `x = y = W_A`, `u = v = phi^T H^T L^-T`.
    pub(crate) fn commit(&mut self, x: &[f64], y: &[f64], u: &[f64], v: &[f64], d: usize) {
        let (na, na0) = (self.n_active(), self.n_a0);
        // y^T, d x n_A column-major.
        let mut y_t = alloc::vec![0.0; d * na];
        for (c, col) in y.chunks_exact(na).enumerate() {
            for (k, &val) in col.iter().enumerate() {
                if let Some(t) = y_t.get_mut(k * d + c) {
                    *t = val;
                }
            }
        }
        rank_update_lower(self.paa.as_mut_slice(), na, x, y, d, -1.0);
        crate::linalg::gemm(&mut self.phit, na0, na, u, &y_t, d, -1.0, true);
        rank_update_lower(&mut self.psi, na0, u, v, d, 1.0);
    }

    /// Row `b` of `P0_{B A0}` dotted with column `k` of `phi^T`: `P_{b, active k}`.
    fn cross(&self, k: usize, b: usize) -> f64 {
        let n0 = self.n0;
        let col = self.phit.get(k * self.n_a0..(k + 1) * self.n_a0);
        col.map_or(f64::NAN, |col| {
            col.iter()
                .enumerate()
                .map(|(t, f)| f * self.g0.get(t * n0 + b).copied().unwrap_or(f64::NAN))
                .sum()
        })
    }

    /// `psi P0_{A0 b}` (length `n_A0`): a symmetric product from `psi`'s lower triangle,
    /// read down its columns.
    fn psi_row(&self, b: usize) -> Vec<f64> {
        let (na0, n0) = (self.n_a0, self.n0);
        let g: Vec<f64> = (0..na0)
            .map(|t| self.g0.get(t * n0 + b).copied().unwrap_or(f64::NAN))
            .collect();
        let mut out = alloc::vec![0.0; na0];
        for (t, col) in self.psi.chunks_exact(na0).enumerate() {
            let (Some(below), Some(g_below), Some(&gt)) = (col.get(t..), g.get(t..), g.get(t))
            else {
                continue;
            };
            let mut acc = 0.0;
            for (p, gu) in below.iter().zip(g_below) {
                acc += p * gu;
            }
            if let Some(o) = out.get_mut(t) {
                *o += acc;
            }
            if let (Some(o), Some(p)) = (out.get_mut(t + 1..), below.get(1..)) {
                for (ov, pv) in o.iter_mut().zip(p) {
                    *ov += pv * gt;
                }
            }
        }
        out
    }

    /// Entry `(i, j)` of the current covariance (state indices), from `P0` (`base`).
    pub(crate) fn entry(&self, base: &[f64], i: usize, j: usize) -> f64 {
        match (self.place.get(i), self.place.get(j)) {
            (Some(&Place::Active(a)), Some(&Place::Active(b))) => {
                sym(self.paa.as_slice(), self.n_active(), a, b)
            }
            (Some(&Place::Active(k)), Some(&Place::Passive(b)))
            | (Some(&Place::Passive(b)), Some(&Place::Active(k))) => self.cross(k, b),
            (Some(&Place::Passive(a)), Some(&Place::Passive(b))) => {
                let row = self.psi_row(a);
                let n0 = self.n0;
                let correction: f64 = row
                    .iter()
                    .enumerate()
                    .map(|(u, v)| v * self.g0.get(u * n0 + b).copied().unwrap_or(f64::NAN))
                    .sum();
                sym(base, n0, a, b) - correction
            }
            _ => f64::NAN,
        }
    }

    /// The `3 x 3` block at `(i, i)`: as [`Local::entry`], with a passive block's `psi`
    /// products formed once.
    pub(crate) fn block3(&self, base: &[f64], i: usize) -> Matrix3<f64> {
        let places: [Option<&Place>; 3] = core::array::from_fn(|r| self.place.get(i + r));
        if let [
            Some(Place::Passive(b0)),
            Some(Place::Passive(_)),
            Some(Place::Passive(_)),
        ] = places
        {
            let b0 = *b0;
            let n0 = self.n0;
            let rows: [Vec<f64>; 3] = core::array::from_fn(|r| self.psi_row(b0 + r));
            return Matrix3::from_fn(|r, c| {
                let correction: f64 = rows[r]
                    .iter()
                    .enumerate()
                    .map(|(u, v)| v * self.g0.get(u * n0 + b0 + c).copied().unwrap_or(f64::NAN))
                    .sum();
                sym(base, n0, b0 + r, b0 + c) - correction
            });
        }
        Matrix3::from_fn(|r, c| self.entry(base, i + r, i + c))
    }
}

impl Local {
    /// `P0_{B A0} psi` for every row of `P0` (`n_0 x n_A0`), one product: what
    /// [`Local::block3_with`] reads the passive blocks from.
    pub(crate) fn passive_products(&self) -> Vec<f64> {
        let (n0, na0) = (self.n0, self.n_a0);
        let mut psi = self.psi.clone();
        crate::linalg::mirror_lower(&mut psi, na0);
        let mut m = alloc::vec![0.0; n0 * na0];
        crate::linalg::gemm(&mut m, n0, na0, &self.g0, &psi, na0, 1.0, false);
        m
    }

    /// [`Local::block3`] with `P0_{B A0} psi` given ([`Local::passive_products`]).
    pub(crate) fn block3_with(&self, base: &[f64], i: usize, m: &[f64]) -> Matrix3<f64> {
        let (n0, na0) = (self.n0, self.n_a0);
        match self.place.get(i) {
            Some(&Place::Passive(b)) => Matrix3::from_fn(|r, c| {
                let correction: f64 = (0..na0)
                    .map(|u| {
                        m.get(u * n0 + b + r).copied().unwrap_or(f64::NAN)
                            * self.g0.get(u * n0 + b + c).copied().unwrap_or(f64::NAN)
                    })
                    .sum();
                sym(base, n0, b + r, b + c) - correction
            }),
            _ => self.block3(base, i),
        }
    }

    /// Entry `(i, j)` of an upper bound of the current covariance in the positive
    /// semi-definite order, `P + [0, 0; 0, P0_BB - P_BB]` (`P0_BB - P_BB = P0_BA0 psi P0_A0B`
    /// is positive semi-definite): the passive block as the session found it, the rest
    /// exact. Costs `O(n_A0)` at most, where [`Local::entry`] costs `O(n_A0^2)`.
    pub(crate) fn entry_upper(&self, base: &[f64], i: usize, j: usize) -> f64 {
        match (self.place.get(i), self.place.get(j)) {
            (Some(&Place::Passive(a)), Some(&Place::Passive(b))) => sym(base, self.n0, a, b),
            _ => self.entry(base, i, j),
        }
    }

    /// The `3 x 3` block at `(i, i)` of that upper bound.
    pub(crate) fn block3_upper(&self, base: &[f64], i: usize) -> Matrix3<f64> {
        Matrix3::from_fn(|r, c| self.entry_upper(base, i + r, i + c))
    }
}

impl Ekf {
    /// Entry `(i, j)` of `P` (state indices), whether or not a local session is open.
    #[inline]
    pub(crate) fn cov(&self, i: usize, j: usize) -> f64 {
        match &self.local {
            None => sym(self.p.as_slice(), self.x.len(), i, j),
            Some(l) => l.entry(self.p.as_slice(), i, j),
        }
    }

    /// Entry `(i, j)` of `P`, or with `upper` of the upper bound [`Local::entry_upper`]
    /// while a local session is open.
    #[inline]
    pub(crate) fn cov_with(&self, i: usize, j: usize, upper: bool) -> f64 {
        match (&self.local, upper) {
            (Some(l), true) => l.entry_upper(self.p.as_slice(), i, j),
            _ => self.cov(i, j),
        }
    }

    /// Whether a local session is open (see [`Ekf::settle`]).
    pub fn is_local(&self) -> bool {
        self.local.is_some()
    }

    /// The active states of the open local session, `None` when none is open.
    pub fn local_states(&self) -> Option<usize> {
        self.local.as_ref().map(|l| l.n_active())
    }

    /// Opens a local session whose active states are the pose, the camera and the landmarks in
    /// `slots` (state order). Settles an open one first.
    pub(crate) fn open_local(&mut self, slots: &[usize]) {
        self.settle();
        let n = self.x.len();
        let layout = self.layout();
        let mut active: Vec<usize> = (0..POSE_DIM).collect();
        let mut sorted: Vec<usize> = slots
            .iter()
            .copied()
            .filter(|&s| s < layout.landmarks)
            .collect();
        sorted.sort_unstable();
        sorted.dedup();
        for s in sorted {
            active.extend(StateLayout::landmark(s)..StateLayout::landmark(s) + LANDMARK_DIM);
        }
        active.extend(layout.camera_start()..n);
        let na = active.len();
        let mut place: Vec<Place> = (0..n).map(Place::Passive).collect();
        for (k, &i) in active.iter().enumerate() {
            if let Some(p) = place.get_mut(i) {
                *p = Place::Active(k);
            }
        }
        let mut g0 = alloc::vec![0.0; n * na];
        gather_columns(self.p.as_slice(), n, &active, &mut g0);
        let paa = DMatrix::from_fn(na, na, |r, c| {
            let (i, j) = (active[r], active[c]);
            sym(self.p.as_slice(), n, i, j)
        });
        let mut phit = alloc::vec![0.0; na * na];
        for k in 0..na {
            phit[k * na + k] = 1.0;
        }
        self.local = Some(alloc::boxed::Box::new(Local {
            place,
            active,
            paa,
            phit,
            psi: alloc::vec![0.0; na * na],
            g0,
            n_a0: na,
            n0: n,
        }));
        self.health.local_sessions += 1;
    }

    /// Closes the local session, if one is open: `P_AB` and `P_BB` are written out (module
    /// docs), `O(n_B^2 n_A0)`. Every reader of the filter gets the same values either way;
    /// this only moves the cost (call it before reading the whole covariance many times).
    pub fn settle(&mut self) {
        let Some(l) = self.local.take() else {
            return;
        };
        let n = self.x.len();
        let (n0, na0, na) = (l.n0, l.n_a0, l.n_active());
        // P0_BB - P0_BA0 psi P0_A0B over all of P0's rows (the active ones are overwritten).
        let mut psi = l.psi.clone();
        crate::linalg::mirror_lower(&mut psi, na0);
        let mut m = alloc::vec![0.0; n0 * na0];
        crate::linalg::gemm(&mut m, n0, na0, &l.g0, &psi, na0, 1.0, false);
        rank_update_lower(self.p.as_mut_slice(), n0, &m, &l.g0, na0, -1.0);
        // P_{B A} = P0_BA0 phi^T.
        let mut c = alloc::vec![0.0; n0 * na];
        crate::linalg::gemm(&mut c, n0, na, &l.g0, &l.phit, na0, 1.0, false);
        // No state added or removed: `P_BB` is already in place and only the active rows and
        // columns are written, `O(n n_A)`; otherwise the whole buffer is written anew.
        let unmoved = n == n0
            && l.place.iter().enumerate().all(|(i, place)| match *place {
                Place::Passive(b) => b == i,
                Place::Active(_) => true,
            });
        if unmoved {
            write_active_in_place(self.p.as_mut_slice(), n, &l, &c);
        } else {
            let p = settled_buffer(self.p.as_slice(), n0, n, &l, &c);
            self.p = DMatrix::from_vec(n, n, p);
        }
        self.health.local_settles += 1;
    }

    /// Prepares the update of the landmarks in `slots`: keeps the open session when they are
    /// all active, settles it when not, and opens one around the vehicle when the state is
    /// large enough and the update has the session's (factored) form.
    pub(crate) fn prepare_local(&mut self, slots: &[usize]) {
        let usable = self.settings.local_margin_m > 0.0 && !self.joseph();
        if !usable {
            self.settle();
            return;
        }
        if let Some(l) = &self.local {
            let all_active = slots.iter().all(|&s| {
                matches!(
                    l.place.get(StateLayout::landmark(s)),
                    Some(Place::Active(_))
                )
            });
            if all_active {
                return;
            }
            self.settle();
        }
        if self.x.len() < LOCAL_MIN_STATES {
            return;
        }
        let chosen = self.session_landmarks(slots);
        self.open_local(&chosen);
    }

    /// A session's active landmarks: `slots`; those the field of use takes
    /// (`StereoField::uses`: the inner cone and the outer band's low-gain part, inside the
    /// lens's images) from any pose within `local_margin_m` in x and y and `local_turn_rad` in
    /// heading of the vehicle's (a 3 x 3 x 3 grid of poses); and those the far band reaches
    /// from the vehicle's pose within `local_margin_m` beyond the farthest one in the field of
    /// use.
    ///
    /// The disc of every landmark within the margin beyond the farthest one in view, the
    /// rule before, held 2.5 times as many in a hall with lamps every 3 m (about 70 for 28
    /// in view: the view's corners swept through every heading), and an update costs the
    /// square of the active block (docs/benchmarks.md, "The session's footprint"). A pair
    /// outside the inner field of a passive landmark is left out, not settled for
    /// (`Ekf::landmark_only_update`): the far band's landmarks within the disc are kept
    /// active, so that as many far pairs are used as the disc used (swept as well, their
    /// reach made a fisheye's sessions larger than the disc; left to the grid of poses
    /// alone, a fisheye hall dropped 26 000 of its 43 000 outer pairs instead of 18 000).
    fn session_landmarks(&self, slots: &[usize]) -> Vec<usize> {
        let (m, turn) = (self.settings.local_margin_m, self.settings.local_turn_rad);
        let base = self.pose();
        let view = self.view();
        let mut chosen: Vec<usize> = slots.to_vec();
        // One projection from the vehicle's pose: what the view reaches, split into what the
        // field of use takes and the far band's rest.
        let (used, far): (Vec<_>, Vec<_>) = self
            .landmarks_in_view_from(&base, true)
            .into_iter()
            .partition(|(_, z)| self.in_view(&view, z, false));
        let distance = |s: usize| {
            let i = StateLayout::landmark(s);
            libm::hypot(self.x[i] - base.x, self.x[i + 1] - base.y)
        };
        let radius = used
            .iter()
            .map(|(s, _)| *s)
            .chain(slots.iter().copied())
            .map(distance)
            .fold(0.0, f64::max)
            + m;
        chosen.extend(used.iter().map(|(s, _)| *s));
        chosen.extend(
            far.iter()
                .map(|(s, _)| *s)
                .filter(|&s| distance(s) <= radius),
        );
        let mut reached = alloc::vec![false; self.landmarks.len()];
        for &s in &chosen {
            if let Some(r) = reached.get_mut(s) {
                *r = true;
            }
        }
        let poses: Vec<rig_model::Projector> = [-m, 0.0, m]
            .into_iter()
            .flat_map(|dx| [-m, 0.0, m].map(|dy| (dx, dy)))
            .flat_map(|(dx, dy)| {
                [-turn, 0.0, turn].map(|dt| {
                    let pose = rig_model::Pose2::new(base.x + dx, base.y + dy, base.theta + dt);
                    rig_model::Projector::new(&view.0, &pose)
                })
            })
            .collect();
        chosen.extend((0..self.landmarks.len()).filter(|&s| {
            reached.get(s) == Some(&false) && poses.iter().any(|p| self.in_use_from(&view, p, s))
        }));
        chosen
    }
}

/// Writes the settled session's active rows and columns into `P0` itself (its lower
/// triangle), when the state's indices did not move during the session: `P_AA` from the
/// session, `P_AB` from `c = P0_BA0 phi^T` (`n x n_A`, column-major).
fn write_active_in_place(p: &mut [f64], n: usize, l: &Local, c: &[f64]) {
    let paa = l.paa.as_slice();
    let na = l.n_active();
    for (k, &s) in l.active.iter().enumerate() {
        // Column `s` from its diagonal down.
        for i in s..n {
            let v = match l.place.get(i) {
                Some(Place::Active(k2)) => sym(paa, na, k, *k2),
                Some(Place::Passive(_)) => c.get(k * n + i).copied().unwrap_or(f64::NAN),
                None => continue,
            };
            if let Some(d) = p.get_mut(s * n + i) {
                *d = v;
            }
        }
        // Row `s` left of the diagonal, in the passive columns (the active ones are written
        // as columns above).
        for j in 0..s {
            if let Some(Place::Passive(_)) = l.place.get(j)
                && let Some(d) = p.get_mut(j * n + s)
            {
                *d = c.get(k * n + j).copied().unwrap_or(f64::NAN);
            }
        }
    }
}

/// A run of consecutive state indices `[start, end)` whose rows live consecutively in one
/// source: `P0`'s rows from `first` on, or `P_AA`'s.
#[derive(Debug, Clone, Copy)]
struct Run {
    start: usize,
    end: usize,
    first: Place,
}

/// The settled covariance's buffer (`n x n`, column-major, the lower triangle; the upper one
/// zero) when the session added or removed states: each column's rows copied run by run from
/// `P0`'s lower triangle, `c = P0_BA0 phi^T` (`n0 x n_A`) or `P_AA`. Memory-bound, `O(n^2)`,
/// written once and in order.
fn settled_buffer(base: &[f64], n0: usize, n: usize, l: &Local, c: &[f64]) -> Vec<f64> {
    let paa = l.paa.as_slice();
    let na = l.n_active();
    let mut runs: Vec<Run> = Vec::new();
    for (i, &place) in l.place.iter().enumerate() {
        let extends = runs.last().is_some_and(|r| {
            let len = i - r.start;
            match (r.first, place) {
                (Place::Passive(a), Place::Passive(b)) => b == a + len,
                (Place::Active(a), Place::Active(b)) => b == a + len,
                _ => false,
            }
        });
        match runs.last_mut() {
            Some(r) if extends => r.end = i + 1,
            _ => runs.push(Run {
                start: i,
                end: i + 1,
                first: place,
            }),
        }
    }
    let mut out: Vec<f64> = Vec::with_capacity(n * n);
    for j in 0..n {
        let column = l.place.get(j).copied();
        out.resize(j * n + j, 0.0);
        for r in &runs {
            if r.end <= j {
                continue;
            }
            let from = r.start.max(j);
            let len = r.end - from;
            let offset = from - r.start;
            match (r.first, column) {
                // P0's lower triangle: rows `a..` of column `b` (a >= b while the order is kept).
                (Place::Passive(a), Some(Place::Passive(b))) => {
                    let a = a + offset;
                    if a >= b {
                        extend_or_nan(&mut out, base.get(b * n0 + a..b * n0 + a + len), len);
                    } else {
                        out.extend((a..a + len).map(|a| sym(base, n0, a, b)));
                    }
                }
                (Place::Passive(a), Some(Place::Active(k))) => {
                    let a = a + offset;
                    extend_or_nan(&mut out, c.get(k * n0 + a..k * n0 + a + len), len);
                }
                (Place::Active(k0), Some(Place::Passive(b))) => {
                    let k0 = k0 + offset;
                    out.extend(
                        (k0..k0 + len).map(|k| c.get(k * n0 + b).copied().unwrap_or(f64::NAN)),
                    );
                }
                // P_AA's lower triangle: rows `k..` of column `kj`.
                (Place::Active(k0), Some(Place::Active(kj))) => {
                    let k0 = k0 + offset;
                    if k0 >= kj {
                        extend_or_nan(&mut out, paa.get(kj * na + k0..kj * na + k0 + len), len);
                    } else {
                        out.extend((k0..k0 + len).map(|k| sym(paa, na, k, kj)));
                    }
                }
                (_, None) => out.extend(core::iter::repeat_n(f64::NAN, len)),
            }
        }
    }
    out.resize(n * n, f64::NAN);
    out
}

/// Appends `src`, or `len` NaNs when it is out of range (a broken session, never silent).
fn extend_or_nan(out: &mut Vec<f64>, src: Option<&[f64]>, len: usize) {
    match src {
        Some(s) => out.extend_from_slice(s),
        None => out.extend(core::iter::repeat_n(f64::NAN, len)),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::cast_precision_loss)]
pub(crate) mod tests {
    use super::*;
    use crate::{LandmarkId, Settings};
    use nalgebra::Vector3;
    use rig_model::camera::Param;
    use rig_model::{Pose2, Rig};

    fn rig() -> Rig {
        crate::filter::tests::rig_estimating(&[(Param::Baseline, 0.005), (Param::F, 5.0)])
    }

    /// Deterministic pixel noise, +-0.3 px.
    pub(crate) struct Lcg(pub(crate) u64);
    impl Lcg {
        pub(crate) fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.6
        }
    }

    /// A drive along a ceiling grid of 144 lamps (a 436-element state), the same steps given
    /// to a dense filter and to one with local sessions: predictions, updates of the lamps
    /// near the vehicle, a landmark added, two removed (one near, one far), one merged. Also
    /// the setting of `crate::marginal`'s tests.
    pub(crate) fn drive(margin: f64) -> Ekf {
        drive_with(Settings {
            local_margin_m: margin,
            ..Settings::default()
        })
    }

    /// [`drive`] with the filter's settings given.
    pub(crate) fn drive_with(settings: Settings) -> Ekf {
        let mut rig = rig();
        if settings.odometry_error_states || settings.odometry_velocity_states {
            // Odometry with memory, its errors as states of the filter (`crate::errors`).
            rig.noise.velocity_tau = 0.6;
            rig.noise.yaw_rate_tau = 0.6;
        }
        let mut ekf = Ekf::from_prior(&rig, settings).unwrap();
        let lamps: Vec<Vector3<f64>> = (0..144)
            .map(|k| Vector3::new(f64::from(k % 12), f64::from(k / 12) - 5.5, 3.0))
            .collect();
        let mut noise = Lcg(7);
        let mut measure = |pose: &Pose2, p: &Vector3<f64>| {
            let mut z = rig_model::project(&rig.nominal, pose, p).unwrap();
            for v in z.iter_mut() {
                *v += noise.next();
            }
            z
        };
        let start = Pose2::default();
        let mut ids: Vec<LandmarkId> = lamps
            .iter()
            .map(|p| ekf.add_landmark(&measure(&start, p)).unwrap())
            .collect();
        let mut truth = start;
        for step in 0..120 {
            let (vx, w) = (0.5, if step < 60 { 0.02 } else { -0.03 });
            if settings.odometry_error_states || settings.odometry_velocity_states {
                let (t0, t1) = (step * 100_000, (step + 1) * 100_000);
                let samples = [t0, t1].map(|t_us| rig_model::odometry::OdomSample {
                    t_us,
                    vx,
                    vy: 0.0,
                    vtheta: w,
                });
                ekf.predict_odometry_vehicle(
                    &samples,
                    (t0, t1),
                    &rig.noise,
                    &rig_model::Vehicle::NOMINAL,
                    &nalgebra::Matrix3x4::zeros(),
                )
                .unwrap();
            } else {
                ekf.predict(vx, 0.0, w, 0.1).unwrap();
            }
            truth = Pose2::new(
                truth.x + vx * 0.1 * truth.theta.cos(),
                truth.y + vx * 0.1 * truth.theta.sin(),
                truth.theta + w * 0.1,
            );
            let batch: Vec<(LandmarkId, rig_model::Measurement)> = lamps
                .iter()
                .zip(&ids)
                .filter(|(p, id)| {
                    ekf.contains(**id) && (libm::hypot(p.x - truth.x, p.y - truth.y) < 1.3)
                })
                .map(|(p, id)| (*id, measure(&truth, p)))
                .collect();
            ekf.update(&batch).unwrap();
            match step {
                30 => {
                    // A second landmark of the lamp nearest the vehicle, merged into the first.
                    let k = (0..lamps.len())
                        .min_by(|&a, &b| {
                            let d = |i: usize| {
                                (lamps[i].xy() - Vector3::new(truth.x, truth.y, 0.0).xy()).norm()
                            };
                            d(a).total_cmp(&d(b))
                        })
                        .unwrap();
                    let twin = ekf.add_landmark(&measure(&truth, &lamps[k])).unwrap();
                    ekf.merge_landmarks(ids[k], twin).unwrap();
                }
                40 => {
                    ekf.remove_landmark(ids[143]).unwrap();
                    let near = ids
                        .iter()
                        .zip(&lamps)
                        .find(|(id, p)| {
                            ekf.contains(**id) && libm::hypot(p.x - truth.x, p.y - truth.y) < 2.0
                        })
                        .map(|(id, _)| *id)
                        .unwrap();
                    ekf.remove_landmark(near).unwrap();
                }
                50 => {
                    let p = Vector3::new(truth.x + 0.4, truth.y - 0.2, 2.9);
                    ids.push(ekf.add_landmark(&measure(&truth, &p)).unwrap());
                }
                _ => {}
            }
        }
        ekf
    }

    /// A session holds the landmarks the view reaches from near the vehicle, not every
    /// landmark within the farthest one's distance: a grid of lamps 2 m apart 8 m up, the
    /// vehicle in its middle.
    #[test]
    fn a_session_holds_the_landmarks_the_view_reaches_from_near_the_vehicle() {
        let rig = rig();
        let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
        let start = Pose2::default();
        let lamps: Vec<Vector3<f64>> = (0..256)
            .map(|k| {
                let at = |i: i32| 2.0 * f64::from(i) - 15.0;
                Vector3::new(at(k % 16), at(k / 16), 8.0)
            })
            .collect();
        // Placed as lamps mapped earlier from where each was seen (straight below it).
        let ids: Vec<LandmarkId> = lamps
            .iter()
            .map(|p| {
                let below = Pose2::new(p.x, p.y, 0.0);
                let z = rig_model::project(&rig.nominal, &below, p).unwrap();
                (ekf.x[0], ekf.x[1]) = (p.x, p.y);
                ekf.add_landmark(&z).unwrap()
            })
            .collect();
        (ekf.x[0], ekf.x[1]) = (start.x, start.y);
        assert!(ekf.x.len() >= LOCAL_MIN_STATES, "{} states", ekf.x.len());
        let visible = ekf.visible_landmarks();
        assert!(!visible.is_empty());
        let batch: Vec<_> = visible.iter().take(4).copied().collect();
        ekf.update(&batch).unwrap();
        let l = ekf.local.as_deref().expect("a session is open");
        let active = |id: LandmarkId| {
            let s = ekf.slot(id).unwrap();
            matches!(
                l.place.get(StateLayout::landmark(s)),
                Some(Place::Active(_))
            )
        };
        // Every landmark in view is active, and every one the view reaches from a pose 1 m
        // off along the grid.
        for (id, _) in &visible {
            assert!(active(*id), "{id} is in view");
        }
        let view = ekf.view();
        for pose in [Pose2::new(1.0, 0.0, 0.0), Pose2::new(-1.0, 1.0, 0.1)] {
            let projector = rig_model::Projector::new(&view.0, &pose);
            for &id in &ids {
                if ekf.in_use_from(&view, &projector, ekf.slot(id).unwrap()) {
                    assert!(active(id), "{id} is in view from {pose:?}");
                }
            }
        }
        // And no other (this rig has no lens, so no far band): each active landmark is
        // reached from one of the 27 poses within the margin and the turn, so a landmark
        // nearer than the farthest active one may stay passive (the disc the rule before took
        // held every such landmark).
        let near: Vec<rig_model::Projector> = [-1.0, 0.0, 1.0]
            .into_iter()
            .flat_map(|dx| [-1.0, 0.0, 1.0].map(|dy| (dx, dy)))
            .flat_map(|(dx, dy)| [-0.1, 0.0, 0.1].map(|dt| Pose2::new(dx, dy, dt)))
            .map(|p| rig_model::Projector::new(&view.0, &p))
            .collect();
        let reached = |id: LandmarkId| {
            let s = ekf.slot(id).unwrap();
            near.iter().any(|p| ekf.in_use_from(&view, p, s))
        };
        let distance = |id: LandmarkId| {
            let p = ekf.landmark_position(id).unwrap();
            libm::hypot(p.x, p.y)
        };
        let active_ids: Vec<LandmarkId> = ids.iter().copied().filter(|&id| active(id)).collect();
        for &id in &active_ids {
            assert!(reached(id), "{id} is active, out of reach");
        }
        let farthest = active_ids
            .iter()
            .map(|&id| distance(id))
            .fold(0.0, f64::max);
        let passive_inside = ids
            .iter()
            .filter(|&&id| !active(id) && distance(id) < farthest)
            .count();
        assert!(
            passive_inside > 0,
            "{} active landmarks, every landmark within {farthest} m",
            active_ids.len()
        );
    }

    #[test]
    fn a_local_session_is_the_dense_filter() {
        a_local_session_is_the_dense_filter_with(false);
    }

    /// The odometry's error states (`crate::errors`) are active in every session: their
    /// prediction, decay and updates in a session are the dense filter's.
    #[test]
    fn a_local_session_with_odometry_error_states_is_the_dense_filter() {
        a_local_session_is_the_dense_filter_with(true);
    }

    /// The same with the velocity-state form: the odometry's measurement of the velocities
    /// and the errors touches active states only.
    #[test]
    fn a_local_session_with_odometry_velocity_states_is_the_dense_filter() {
        let settings = |margin: f64| Settings {
            local_margin_m: margin,
            odometry_velocity_states: true,
            ..Settings::default()
        };
        compare(drive_with(settings(0.0)), drive_with(settings(1.0)));
    }

    fn a_local_session_is_the_dense_filter_with(error_states: bool) {
        let settings = |margin: f64| Settings {
            local_margin_m: margin,
            odometry_error_states: error_states,
            ..Settings::default()
        };
        let dense = drive_with(settings(0.0));
        assert_eq!(dense.error_axes().len(), if error_states { 3 } else { 0 });
        compare(dense, drive_with(settings(1.0)));
    }

    /// A dense filter and one with local sessions after the same drive.
    fn compare(dense: Ekf, mut local: Ekf) {
        assert_eq!(dense.health().local_sessions, 0);
        let health = local.health();
        assert!(health.local_sessions >= 2, "{health:?}");
        assert!(health.local_settles >= 1, "{health:?}");
        assert!(local.is_local());
        // Read while the session is open (to rounding: the session sums in another order),
        // then settled.
        let close = |a: &DMatrix<f64>, b: &DMatrix<f64>| {
            let scale = a.abs().max();
            let diff = (a - b).abs().max();
            assert!(diff <= 1e-8 * scale, "differs by {diff} of {scale}");
        };
        let (a, b) = (
            dense.landmarks().nth(70).unwrap(),
            local.landmarks().nth(70).unwrap(),
        );
        let dyn3 = |m: &Matrix3<f64>| DMatrix::from_column_slice(3, 3, m.as_slice());
        close(&dyn3(&a.covariance), &dyn3(&b.covariance));
        let pose = local.pose_covariance();
        close(&dyn3(&dense.pose_covariance()), &dyn3(&pose));
        let p_open = local.covariance();
        local.settle();
        assert!(!local.is_local());
        let p_local = local.covariance();
        assert_eq!(p_open, p_local);
        assert_eq!(dense.state_len(), local.state_len());
        close(&dense.covariance(), &p_local);
        // To rounding: 1e-10 of the state's scale (12 m). With the first-estimates
        // Jacobians the two forms' rounding grows to about 3e-9 m over this drive (it was
        // under 1e-9 without them); no step of the session is approximate.
        let dx = (dense.state() - local.state()).abs().max();
        assert!(dx < 1e-8, "state differs by {dx}");
    }
}
