//! The map's landmarks: their ids and bookkeeping, initialisation from one stereo measurement
//! with the joint linearised covariance (see the crate docs), removal, and what a caller reads
//! of them.

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rig_model::{Measurement, N_PARAMS};

use crate::error::Error;
use crate::filter::Ekf;
use crate::kernels::gather_columns;
use crate::linalg::mirror_lower;
use crate::state::{LANDMARK_DIM, POSE_DIM, StateLayout, at};

/// A landmark's id: stable for its life, never reused after it is removed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LandmarkId(pub u64);

impl core::fmt::Display for LandmarkId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "landmark {}", self.0)
    }
}

/// What a caller sees of one landmark.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkEstimate {
    /// Its id.
    pub id: LandmarkId,
    /// Position in the world frame, metres.
    pub position: Vector3<f64>,
    /// Its covariance.
    pub covariance: Matrix3<f64>,
    /// Measurements used: the one that initialised it and every accepted one since.
    pub observations: u64,
}

/// How far apart the merge guard's two landmarks of one lamp may be, one sigma on each axis,
/// metres ([`Ekf::merge_landmarks`]): a lamp is not a point, and its two landmarks may come
/// from different views of it, one through the lens's edge. As an exact constraint, the
/// merge of a twin pair phase 1 handed over (one landmark seen ahead, the other 7 s later 57
/// degrees off the axis) read their difference across the ray, known to 2.6 mm and 89 %
/// correlated with the odometry's held yaw bias, as the heading of the whole map beyond a
/// dark stretch: the heading's sigma from 3.9 to 1.6 degrees in one merge, with the map 3.4
/// degrees off (hall 17 of `hall_mc 8 11 --lens radtan --odometry-tau 0.6`; docs/vehicle.md,
/// "Dark stretches").
pub const MERGE_POINT_SIGMA_M: f64 = 0.02;

/// Per-landmark bookkeeping, in state order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Slot {
    pub(crate) id: LandmarkId,
    /// The linearisation point of its observations' Jacobians (`Ekf::observation_model`).
    /// With `Settings::follow_points` (the default), its estimate where the covariance last
    /// took it (placed, handed over, or moved with [`Ekf::shear_linearisation_point`]), for
    /// every landmark. Without: its position when added, following its estimate until
    /// `settled`; `None` for the landmarks handed over by phase 1 (linearised at their
    /// estimate).
    pub(crate) first: Option<Vector3<f64>>,
    pub(crate) observations: u64,
    pub(crate) rejections_in_a_row: u32,
    /// Whether the landmark is known to [`crate::FEJ_SETTLE_SIGMA_M`] with the camera
    /// learned: the iterated update relinearises its observation (and, without
    /// `Settings::follow_points`, `first` stops following the estimate).
    pub(crate) settled: bool,
    /// With `Settings::follow_points` (the default), how the covariance holds the landmark's
    /// placement in the camera ([`Placement`]); `None` without it, or where no stereo pair
    /// from the placing pose sees the point.
    pub(crate) placement: Option<Placement>,
}

/// A landmark's placement as the covariance holds it: the pose it was placed from and its
/// derivative in every camera parameter at its linearisation point, as a stereo pair from
/// that pose sees it (`L = pose * mount * (B / d) (u - cx, v - cy, f)`).
///
/// Kept because a column must be re-linearised absolutely, not by the point's move: the
/// focal length's column is `R (0, 0, z / f) = R (0, 0, B / d)`, unchanged when the focal
/// length is refined and the landmark's depth with it; only a change of the disparity the
/// point stands for moves it. Taken as the move `d` times the column's derivative at the
/// current camera, it was sheared on every refinement of `f` (the paper's square, whose `f`
/// starts 2.5 % off, ended 6.9 sigma off; docs/halls.md, "The linearisation point").
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Placement {
    /// The vehicle's pose it was placed from (handed over: the pose at the hand-over).
    pub(crate) pose: rig_model::Pose2,
    /// `dL/dC` at the linearisation point and the camera of the last re-linearisation, every
    /// parameter's column (those not estimated unused).
    pub(crate) columns: rig_model::rig::Jac3xC,
}

impl Placement {
    /// The placement's camera columns for a landmark at `at` placed from `pose`, with the
    /// camera `camera`: the stereo pair it would see of it there, triangulated back
    /// ([`rig_model::Triangulation::jac_camera_in_world`]). `None` when no pair from that
    /// pose sees the point (behind the cameras, no disparity). The camera is the caller's to
    /// read where the state's rows agree with its landmarks (not while a landmark is being
    /// added or handed over: `Ekf::camera` then reads a landmark's rows).
    pub(crate) fn at(
        camera: &rig_model::CameraParams,
        pose: &rig_model::Pose2,
        at: &Vector3<f64>,
    ) -> Option<Self> {
        let z = rig_model::project(camera, pose, at).ok()?;
        let tri = rig_model::triangulate(camera, &z).ok()?;
        let columns = tri.jac_camera_in_world(camera, pose);
        columns.iter().all(|v| v.is_finite()).then_some(Self {
            pose: *pose,
            columns,
        })
    }
}

impl Ekf {
    /// Landmarks in the map.
    pub fn landmark_count(&self) -> usize {
        self.landmarks.len()
    }

    /// Whether a landmark is in the map.
    pub fn contains(&self, id: LandmarkId) -> bool {
        self.slot(id).is_some()
    }

    /// Position of a landmark in the state order (ids increase along it).
    pub(crate) fn slot(&self, id: LandmarkId) -> Option<usize> {
        self.landmarks.binary_search_by_key(&id, |s| s.id).ok()
    }

    /// Index in the state of a landmark's `x` (then `y`, `z`).
    pub fn landmark_state_index(&self, id: LandmarkId) -> Option<usize> {
        self.slot(id).map(StateLayout::landmark)
    }

    fn estimate_at(&self, s: usize, slot: &Slot) -> LandmarkEstimate {
        let i = StateLayout::landmark(s);
        LandmarkEstimate {
            id: slot.id,
            position: self.x.fixed_rows::<3>(i).into_owned(),
            covariance: self.block3(i),
            observations: slot.observations,
        }
    }

    /// One landmark's estimate.
    pub fn landmark(&self, id: LandmarkId) -> Option<LandmarkEstimate> {
        let s = self.slot(id)?;
        self.landmarks.get(s).map(|slot| self.estimate_at(s, slot))
    }

    /// Measurements a landmark has used (the one that initialised it and every accepted one).
    pub fn observations_of(&self, id: LandmarkId) -> Option<u64> {
        let s = self.slot(id)?;
        self.landmarks.get(s).map(|slot| slot.observations)
    }

    /// A landmark's linearisation point for the first-estimates Jacobians
    /// (`crate::FEJ_SETTLE_SIGMA_M`): `None` for an unknown landmark or one without it (a
    /// landmark handed over by phase 1 without `Settings::follow_points`, linearised at its
    /// estimate). For tests and tools.
    pub fn linearisation_point(&self, id: LandmarkId) -> Option<Vector3<f64>> {
        let s = self.slot(id)?;
        self.landmarks.get(s).and_then(|slot| slot.first)
    }

    /// Every landmark's estimate, in state order (increasing id).
    pub fn landmarks(&self) -> impl Iterator<Item = LandmarkEstimate> + '_ {
        // While a local session is open, the passive landmarks' blocks share one product
        // (`P0_BA0 psi`, formed once here).
        let shared = self.local.as_ref().map(|l| l.passive_products());
        self.landmarks.iter().enumerate().map(move |(s, slot)| {
            let i = StateLayout::landmark(s);
            match (&self.local, &shared) {
                (Some(l), Some(m)) => LandmarkEstimate {
                    id: slot.id,
                    position: self.x.fixed_rows::<3>(i).into_owned(),
                    covariance: l.block3_with(self.p.as_slice(), i, m),
                    observations: slot.observations,
                },
                _ => self.estimate_at(s, slot),
            }
        })
    }

    /// One landmark's position: [`Ekf::landmark`] without the covariance.
    pub fn landmark_position(&self, id: LandmarkId) -> Option<Vector3<f64>> {
        let i = StateLayout::landmark(self.slot(id)?);
        Some(self.x.fixed_rows::<3>(i).into_owned())
    }

    /// Every landmark's id and position, in state order: [`Ekf::landmarks`] without the
    /// covariances (which cost more to read while a local session is open, `crate::local`).
    pub fn landmark_positions(&self) -> impl Iterator<Item = (LandmarkId, Vector3<f64>)> + '_ {
        self.landmarks.iter().enumerate().map(|(s, slot)| {
            (
                slot.id,
                self.x
                    .fixed_rows::<3>(StateLayout::landmark(s))
                    .into_owned(),
            )
        })
    }

    /// How far apart two landmarks are in their joint uncertainty: the squared Mahalanobis
    /// distance of `a - b` under its covariance `P_aa + P_bb - P_ab - P_ba` (3 dof). Small
    /// (below the 3-dof chi-square bound) when they may be one point seen twice.
    pub fn landmark_pair_distance(&self, a: LandmarkId, b: LandmarkId) -> Result<f64, Error> {
        Ok(self.pair_difference(a, b, false)?.d2)
    }

    /// A lower bound of [`Ekf::landmark_pair_distance`] that costs less while a local session
    /// is open (the distance under an upper bound of the covariance, `crate::local`); the
    /// distance itself when none is. For a first test of many pairs: a pair whose bound is
    /// outside a gate is outside it.
    pub fn landmark_pair_distance_bound(&self, a: LandmarkId, b: LandmarkId) -> Result<f64, Error> {
        Ok(self.pair_difference(a, b, true)?.d2)
    }

    /// `a - b`, its covariance's Cholesky factor and the squared Mahalanobis distance (with
    /// `upper`, under the upper bound of the covariance while a local session is open).
    fn pair_difference(
        &self,
        a: LandmarkId,
        b: LandmarkId,
        upper: bool,
    ) -> Result<PairDifference, Error> {
        let ia = self
            .slot(a)
            .map(StateLayout::landmark)
            .ok_or(Error::UnknownLandmark { id: a })?;
        let ib = self
            .slot(b)
            .map(StateLayout::landmark)
            .ok_or(Error::UnknownLandmark { id: b })?;
        let d = self.x.fixed_rows::<3>(ia) - self.x.fixed_rows::<3>(ib);
        let cross = Matrix3::from_fn(|r, c| self.cov_with(ia + r, ib + c, upper));
        let block = |i: usize| match (&self.local, upper) {
            (Some(l), true) => l.block3_upper(self.p.as_slice(), i),
            _ => self.block3(i),
        };
        let s = block(ia) + block(ib) - cross - cross.transpose();
        let c = s
            .cholesky()
            .ok_or(Error::PairNotPositiveDefinite { a, b })?;
        let d2 = d.dot(&c.solve(&d));
        Ok(PairDifference { ia, ib, d, s, d2 })
    }

    /// Merges landmark `drop` into `keep`, two estimates of one point (a lamp mapped twice):
    /// the constraint `x_keep - x_drop = 0` applied as a measurement (a Kalman update with
    /// `H = [.. I .. -I ..]` and the noise [`MERGE_POINT_SIGMA_M`] on each axis), which moves
    /// `keep`, the pose, the camera and every correlated landmark by what `drop` knew and
    /// shrinks their covariance accordingly;
    /// then `drop`, now a copy of `keep`, leaves the state. Returns the squared Mahalanobis
    /// distance the two were apart ([`Ekf::landmark_pair_distance`]); the caller gates on it.
    /// `O(n^2)` in the state's length.
    pub fn merge_landmarks(&mut self, keep: LandmarkId, drop: LandmarkId) -> Result<f64, Error> {
        if keep == drop {
            return Err(Error::MergeIntoItself { id: keep });
        }
        let PairDifference { ia, ib, d, s, d2 } = self.pair_difference(keep, drop, false)?;
        // The constraint's noise: one point to within what one lamp's features are.
        let noise = MERGE_POINT_SIGMA_M * MERGE_POINT_SIGMA_M;
        let c = (s + Matrix3::identity() * noise)
            .cholesky()
            .ok_or(Error::PairNotPositiveDefinite { a: keep, b: drop })?;
        if self.local.is_some() && !self.local_merge(ia, ib, &d, noise)? {
            self.settle();
        }
        if self.local.is_none() {
            let n = self.x.len();
            // The whole of `P` (its lower triangle is kept; the update below is dense).
            mirror_lower(self.p.as_mut_slice(), n);
            // P H^T (n x 3): the covariance of the state with x_keep - x_drop.
            let pht = self.p.columns(ia, 3) - self.p.columns(ib, 3);
            // K = P H^T S^-1, solved column-block by column-block through S's Cholesky factor.
            let k = c.solve(&pht.transpose()).transpose();
            // x += K (0 - (x_keep - x_drop)); P -= K S K^T = K (P H^T)^T.
            self.x -= &k * d;
            self.p -= &k * pht.transpose();
            // The lower triangle, symmetric to rounding (the upper one is not read).
            for j in 0..n {
                for i in j + 1..n {
                    self.p[(i, j)] = 0.5 * (self.p[(i, j)] + self.p[(j, i)]);
                }
            }
        }
        let observations = self.observations_of(drop).unwrap_or(0);
        self.remove_landmark(drop)?;
        if let Some(s) = self.slot(keep)
            && let Some(slot) = self.landmarks.get_mut(s)
        {
            slot.observations += observations;
        }
        Ok(d2)
    }

    /// Adds a landmark triangulated from a measurement at the current pose and camera, with
    /// its joint linearised covariance and cross-covariances (see the crate docs).
    pub fn add_landmark(&mut self, z: &Measurement) -> Result<LandmarkId, Error> {
        if let Some(&value) = z.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "measurement of a new landmark",
                value,
            });
        }
        let camera = self.camera();
        let pose = self.pose();
        let tri =
            rig_model::triangulate(&camera, z).map_err(|source| Error::Triangulation { source })?;
        let position = tri.p_in_world(&camera, &pose);
        if let Some(&value) = position.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "triangulated landmark",
                value,
            });
        }
        let c0 = self.camera_offset();
        let m = self.estimated.len();
        // G = [Gp | Gc] over the involved states (pose, estimated camera).
        let gp = tri.jac_pose(&camera, &pose);
        let gc_full = tri.jac_camera_in_world(&camera, &pose);
        let mut idx: [usize; POSE_DIM + N_PARAMS] = [0; POSE_DIM + N_PARAMS];
        let mut g = [[0.0; POSE_DIM + N_PARAMS]; 3];
        for k in 0..POSE_DIM {
            idx[k] = k;
            for a in 0..3 {
                g[a][k] = gp[(a, k)];
            }
        }
        for (k, p) in self.estimated.iter().enumerate() {
            idx[POSE_DIM + k] = c0 + k;
            for a in 0..3 {
                g[a][POSE_DIM + k] = gc_full[(a, p.index())];
            }
        }
        let q = POSE_DIM + m;
        // The measurement's part of P_LL, Gz R Gz^T, Gz the measurement Jacobian in the world
        // frame.
        let world_from_rig =
            pose.world_from_robot_rotation() * camera.mount.robot_from_rig_rotation();
        let gz = world_from_rig * tri.jac_measurement;
        let noise = if self.pixel_noise.is_uniform() {
            let r2 = self.noise.pixel * self.noise.pixel;
            gz * gz.transpose() * r2
        } else {
            let r = nalgebra::Vector4::from(self.measurement_variances(z));
            gz * nalgebra::Matrix4::from_diagonal(&r) * gz.transpose()
        };
        self.insert_landmark(position, &idx, &g, q, &noise)
    }

    /// Adds a landmark seen as a point relative to the vehicle (`position`: x ahead, y left,
    /// the height in the world; `covariance` its covariance), placed from the current pose
    /// with its joint linearised covariance and cross-covariances, as
    /// [`Ekf::add_landmark`] does from pixels: a lamp held out of the map while the pose was
    /// lost, mapped once the loop is closed.
    pub fn add_landmark_relative(
        &mut self,
        position: &Vector3<f64>,
        covariance: &Matrix3<f64>,
    ) -> Result<LandmarkId, Error> {
        if let Some(&value) = position
            .iter()
            .chain(covariance.iter())
            .find(|v| !v.is_finite())
        {
            return Err(Error::NonFinite {
                what: "relative position of a new landmark",
                value,
            });
        }
        let pose = self.pose();
        let (s, c) = (libm::sin(pose.theta), libm::cos(pose.theta));
        let (vx, vy) = (position.x, position.y);
        let world = Vector3::new(
            pose.x + c * vx - s * vy,
            pose.y + s * vx + c * vy,
            position.z,
        );
        let rot = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        let noise = rot * covariance * rot.transpose();
        let mut idx: [usize; POSE_DIM + N_PARAMS] = [0; POSE_DIM + N_PARAMS];
        let mut g = [[0.0; POSE_DIM + N_PARAMS]; 3];
        for (k, i) in idx.iter_mut().enumerate().take(POSE_DIM) {
            *i = k;
        }
        // d world / d (x, y, theta); the camera's columns are zero (the relative position
        // carries its own uncertainty).
        g[0][0] = 1.0;
        g[1][1] = 1.0;
        g[0][2] = -s * vx - c * vy;
        g[1][2] = c * vx - s * vy;
        self.insert_landmark(world, &idx, &g, POSE_DIM, &noise)
    }

    /// Adds a landmark triangulated from several frames (`crate::views`): `position` in
    /// the world, `camera_jacobian` its derivative in every camera parameter, `noise` its
    /// covariance from the pixels and the dead reckoning over those frames. The frames'
    /// poses are the filter's, whose error is the current pose's to first order (the dead
    /// reckoning between them is in `noise`), so the landmark moves rigidly with the pose.
    pub(crate) fn add_landmark_from_views(
        &mut self,
        position: &Vector3<f64>,
        camera_jacobian: &rig_model::rig::Jac3xC,
        noise: &Matrix3<f64>,
    ) -> Result<LandmarkId, Error> {
        if let Some(&value) = position
            .iter()
            .chain(noise.iter())
            .chain(camera_jacobian.iter())
            .find(|v| !v.is_finite())
        {
            return Err(Error::NonFinite {
                what: "landmark triangulated from several frames",
                value,
            });
        }
        let pose = self.pose();
        let c0 = self.camera_offset();
        let mut idx: [usize; POSE_DIM + N_PARAMS] = [0; POSE_DIM + N_PARAMS];
        let mut g = [[0.0; POSE_DIM + N_PARAMS]; 3];
        for (k, i) in idx.iter_mut().enumerate().take(POSE_DIM) {
            *i = k;
        }
        let carried = carried_by_pose(&pose, position);
        for (a, row) in g.iter_mut().enumerate() {
            for (k, v) in row.iter_mut().enumerate().take(POSE_DIM) {
                *v = carried[(a, k)];
            }
        }
        for (k, p) in self.estimated.iter().enumerate() {
            idx[POSE_DIM + k] = c0 + k;
            for (a, row) in g.iter_mut().enumerate() {
                row[POSE_DIM + k] = camera_jacobian[(a, p.index())];
            }
        }
        let q = POSE_DIM + self.estimated.len();
        self.insert_landmark(*position, &idx, &g, q, noise)
    }

    /// A landmark's linearisation point moved to its estimate, the covariance with it
    /// ([`Self::shear_linearisation_point`]); nothing moves while the point cannot be (the
    /// landmark passive in an open local session).
    pub(crate) fn follow_estimate(&mut self, s: usize) {
        let at = self
            .x
            .fixed_rows::<3>(StateLayout::landmark(s))
            .into_owned();
        if let Some(point) = self.landmarks.get(s).and_then(|l| l.first)
            && point != at
            && self.shear_linearisation_point(s, &(at - point))
            && let Some(slot) = self.landmarks.get_mut(s)
        {
            slot.first = Some(at);
        }
    }

    /// Re-linearises the landmark in slot `s`'s initialisation at a point moved by `d`
    /// (metres): `P <- T P T^T`, `T` the identity but for the landmark's rows, which gain
    /// `(J d) e_theta^T` and, for each estimated camera parameter `c`, `(g_c(new) - g_c) e_c^T`:
    /// `J` the planar quarter turn, `g_c` the placement's column in `c` as the covariance
    /// holds it ([`Placement`]) and `g_c(new)` the same at the new point and the current
    /// camera. A landmark placed from the pose and the camera moves with the heading by
    /// `J (L - p)` and with the camera by its columns (with the baseline by `(L - C) / B`,
    /// `C` the camera; with the focal length along the optical axis by `B / d`); the
    /// covariance took them at the point it was placed at, and the update's Jacobians are
    /// taken at the linearisation point. Moved without this, the point leaves the
    /// covariance's unobservable turn of the world (the landmark at `J (L - c)` for a turn
    /// about `c`) behind the Jacobians', and every update of the landmark told the filter
    /// its heading (docs/halls.md, "The linearisation point"). `T` is invertible: no
    /// information is made or lost. Without a placement (none held, or no pair from its pose
    /// sees the new point) the baseline's column moves by `d / B` and no other camera column
    /// moves; the landmark then holds none.
    /// Returns whether it was applied (not to a landmark passive in an open local session).
    pub(crate) fn shear_linearisation_point(&mut self, s: usize, d: &Vector3<f64>) -> bool {
        let i = StateLayout::landmark(s);
        let mut shears: Vec<(usize, [f64; 3])> = alloc::vec![(2, [-d.y, d.x, 0.0])];
        let slot = self.landmarks.get(s).copied();
        let point = slot.and_then(|l| l.first);
        let camera = self.camera();
        let moved = match (slot.and_then(|l| l.placement), point) {
            (Some(old), Some(point)) => {
                Placement::at(&camera, &old.pose, &(point + d)).map(|new| (old, new))
            }
            _ => None,
        };
        let c0 = self.camera_offset();
        match &moved {
            Some((old, new)) => {
                for (k, p) in self.estimated.iter().enumerate() {
                    let g = new.columns.column(p.index()) - old.columns.column(p.index());
                    if g.iter().any(|v| *v != 0.0) {
                        shears.push((c0 + k, [g.x, g.y, g.z]));
                    }
                }
            }
            None => {
                if let Some(k) = self
                    .estimated
                    .iter()
                    .position(|p| *p == rig_model::camera::Param::Baseline)
                {
                    let b = camera.baseline;
                    shears.push((c0 + k, [d.x / b, d.y / b, d.z / b]));
                }
            }
        }
        let applied = self.transform_target_rows([i, i + 1, i + 2], [1.0; 3], &shears);
        // Without a new placement the baseline's column moved by `d / B` alone: the held
        // columns no longer say what the covariance holds, and are dropped for good.
        if applied && let Some(slot) = self.landmarks.get_mut(s) {
            slot.placement = moved.map(|(_, new)| new);
        }
        applied
    }

    /// `P <- T P T^T` with `T = D + sum_s a_s e_s^T` the identity but for the three `targets`
    /// rows (row `targets[r]` scaled by `scale[r]`, plus `a_s[r]` times source row `s` for
    /// every `(s, a_s)` of `sources`; no source is a target): dense, or in an open local
    /// session on `P_AA` and `phi`'s rows (`P_BA`'s share). Returns whether it was applied
    /// (not when a target or a source is passive in the session). The landmarks' shears
    /// ([`Self::shear_linearisation_point`]) and the scale's correction (`crate::scale`).
    pub(crate) fn transform_target_rows(
        &mut self,
        targets: [usize; 3],
        scale: [f64; 3],
        sources: &[(usize, [f64; 3])],
    ) -> bool {
        match self.local.as_deref_mut() {
            None => {
                let n = self.p.nrows();
                shear_rows(self.p.as_mut_slice(), n, targets, scale, sources);
                true
            }
            Some(l) => {
                let place = |c: usize| match l.place.get(c) {
                    Some(&crate::local::Place::Active(k)) => Some(k),
                    _ => None,
                };
                let (Some(k0), Some(k1), Some(k2)) =
                    (place(targets[0]), place(targets[1]), place(targets[2]))
                else {
                    return false;
                };
                let Some(local): Option<Vec<(usize, [f64; 3])>> = sources
                    .iter()
                    .map(|(src, a)| place(*src).map(|k| (k, *a)))
                    .collect()
                else {
                    return false;
                };
                let na = l.paa.nrows();
                let na0 = l.n_a0;
                shear_rows(l.paa.as_mut_slice(), na, [k0, k1, k2], scale, &local);
                // phi's rows by the same transform (`P_BA`'s share).
                for (k, d) in [k0, k1, k2].into_iter().zip(scale) {
                    if d != 1.0
                        && let Some(row) = l.phit.get_mut(k * na0..(k + 1) * na0)
                    {
                        for v in row {
                            *v *= d;
                        }
                    }
                }
                for (ks, a) in local {
                    for t in 0..na0 {
                        let src = l.phit.get(ks * na0 + t).copied().unwrap_or(0.0);
                        for (k, ak) in [k0, k1, k2].into_iter().zip(a) {
                            if let Some(v) = l.phit.get_mut(k * na0 + t) {
                                *v += ak * src;
                            }
                        }
                    }
                }
                true
            }
        }
    }

    /// Every landmark's estimate as its linearisation point (after a joint estimate from
    /// outside, `Ekf::set_joint`, `Ekf::replace_marginal`, whose covariance was taken at the
    /// estimate), its placement's columns taken there; the landmarks without one (handed over
    /// by phase 1 without `Settings::follow_points`) keep none.
    pub(crate) fn relinearise_landmarks(&mut self) {
        let camera = self.camera();
        for k in 0..self.landmarks.len() {
            let at = self
                .x
                .fixed_rows::<3>(StateLayout::landmark(k))
                .into_owned();
            let placement = self
                .landmarks
                .get(k)
                .and_then(|l| l.placement)
                .and_then(|old| Placement::at(&camera, &old.pose, &at));
            if let Some(slot) = self.landmarks.get_mut(k)
                && slot.first.is_some()
            {
                slot.first = Some(at);
                slot.placement = placement;
            }
        }
    }

    /// Appends a landmark at `position` whose covariance is `G P Gᵀ + noise` over the states
    /// `idx[..q]` (`g` their Jacobian rows) and whose cross-covariances are `G P`.
    fn insert_landmark(
        &mut self,
        position: Vector3<f64>,
        idx: &[usize; POSE_DIM + N_PARAMS],
        g: &[[f64; POSE_DIM + N_PARAMS]; 3],
        q: usize,
        noise: &Matrix3<f64>,
    ) -> Result<LandmarkId, Error> {
        if self.landmark_count() >= self.settings.max_landmarks {
            return Err(Error::LandmarkCap {
                cap: self.settings.max_landmarks,
            });
        }
        // Read before the state grows (the camera's rows move).
        let placement = if self.settings.follow_points {
            Placement::at(&self.camera(), &self.pose(), &position)
        } else {
            None
        };
        let n = self.x.len();
        let c0 = self.camera_offset();
        // The camera block and the odometry's errors after it move down together.
        let m = self.layout().tail();
        let (idx, g, noise) = (*idx, *g, *noise);
        match self.local.as_deref_mut() {
            None => self.p = grow(&self.p, c0, &idx[..q], &g, &noise)?,
            Some(l) => {
                // The same in P_AA (the camera block starts at its row kc0, the last `m`
                // active rows with the odometry's errors), and the new rows
                // of phi: G phi over the involved rows.
                let kc0 = l.n_active() - m;
                let mut local_idx = idx;
                for (t, v) in local_idx.iter_mut().enumerate().take(q) {
                    *v = if t < POSE_DIM { t } else { kc0 + t - POSE_DIM };
                }
                let paa = grow(&l.paa, kc0, &local_idx[..q], &g, &noise)?;
                let na0 = l.n_a0;
                let mut rows = alloc::vec![0.0; LANDMARK_DIM * na0];
                for (a, row) in rows.chunks_exact_mut(na0).enumerate() {
                    for (t, &k) in local_idx.iter().enumerate().take(q) {
                        let gat = g[a][t];
                        if gat == 0.0 {
                            continue;
                        }
                        if let Some(col) = l.phit.get(k * na0..(k + 1) * na0) {
                            for (r, &f) in row.iter_mut().zip(col) {
                                *r += gat * f;
                            }
                        }
                    }
                }
                l.paa = paa;
                l.phit.splice(kc0 * na0..kc0 * na0, rows);
                for place in &mut l.place {
                    if let crate::local::Place::Active(k) = place
                        && *k >= kc0
                    {
                        *k += LANDMARK_DIM;
                    }
                }
                l.place.splice(
                    c0..c0,
                    (0..LANDMARK_DIM).map(|a| crate::local::Place::Active(kc0 + a)),
                );
                for i in &mut l.active {
                    if *i >= c0 {
                        *i += LANDMARK_DIM;
                    }
                }
                l.active.splice(kc0..kc0, c0..c0 + LANDMARK_DIM);
            }
        }
        let n2 = n + LANDMARK_DIM;
        let mut x2 = DVector::<f64>::zeros(n2);
        x2.rows_mut(0, c0).copy_from(&self.x.rows(0, c0));
        x2.fixed_rows_mut::<3>(c0).copy_from(&position);
        x2.rows_mut(c0 + LANDMARK_DIM, m)
            .copy_from(&self.x.rows(c0, m));
        self.x = x2;
        let id = LandmarkId(self.next_id);
        self.next_id += 1;
        self.landmarks.push(Slot {
            id,
            first: Some(position),
            observations: 1,
            rejections_in_a_row: 0,
            settled: false,
            placement,
        });
        self.health.landmarks_added += 1;
        Ok(id)
    }

    /// Removes a landmark: its rows and columns leave the state.
    pub fn remove_landmark(&mut self, id: LandmarkId) -> Result<(), Error> {
        let s = self.slot(id).ok_or(Error::UnknownLandmark { id })?;
        let n = self.x.len();
        let li = StateLayout::landmark(s);
        let keep = |i: usize| if i < li { i } else { i + LANDMARK_DIM };
        match self.local.as_deref_mut() {
            None => self.p = shrink(&self.p, li),
            Some(l) => {
                // An active landmark leaves P_AA and phi; a passive one only the index.
                if let Some(&crate::local::Place::Active(k)) = l.place.get(li) {
                    l.paa = shrink(&l.paa, k);
                    let na0 = l.n_a0;
                    l.phit.drain(k * na0..(k + LANDMARK_DIM) * na0);
                    for place in &mut l.place {
                        if let crate::local::Place::Active(j) = place
                            && *j > k
                        {
                            *j -= LANDMARK_DIM;
                        }
                    }
                    l.active.drain(k..k + LANDMARK_DIM);
                }
                l.place.drain(li..li + LANDMARK_DIM);
                for i in &mut l.active {
                    if *i > li {
                        *i -= LANDMARK_DIM;
                    }
                }
            }
        }
        let x2 = DVector::from_fn(n - LANDMARK_DIM, |i, _| self.x[keep(i)]);
        self.x = x2;
        self.landmarks.remove(s);
        self.health.landmarks_removed += 1;
        Ok(())
    }
}

/// `p` (`n x n`, lower triangle) with a new landmark's rows and columns inserted at `c0`:
/// its cross-covariance `P_xL = P[:, idx] G^T` (`idx` the involved states, pose and estimated
/// camera, and `g` the initialisation's Jacobian over them) and `P_LL = G P_qq G^T + noise`.
/// Fails, changing nothing, when a value is not finite. `O(n^2)` (the copy).
fn grow(
    p: &DMatrix<f64>,
    c0: usize,
    idx: &[usize],
    g: &[[f64; POSE_DIM + N_PARAMS]; 3],
    noise: &Matrix3<f64>,
) -> Result<DMatrix<f64>, Error> {
    let n = p.nrows();
    let q = idx.len();
    // Cross covariance P_xL (n x 3): column a = sum_t G[a][t] P[:, idx[t]].
    let mut columns = alloc::vec![0.0; n * q];
    gather_columns(p.as_slice(), n, idx, &mut columns);
    let mut cross = [Vec::new(), Vec::new(), Vec::new()];
    for (a, col) in cross.iter_mut().enumerate() {
        col.resize(n, 0.0);
        for (t, pcol) in columns.chunks_exact(n).enumerate() {
            let gat = g[a][t];
            if gat == 0.0 {
                continue;
            }
            for (c, &p) in col.iter_mut().zip(pcol) {
                *c += gat * p;
            }
        }
    }
    let mut pll = *noise;
    for a in 0..3 {
        for b in 0..3 {
            let mut v = 0.0;
            for (t, &i) in idx.iter().enumerate() {
                v += g[a][t] * cross[b].get(i).copied().unwrap_or(f64::NAN);
            }
            pll[(a, b)] += v;
        }
    }
    let pll = 0.5 * (pll + pll.transpose());
    if pll.iter().any(|v| !v.is_finite()) || cross.iter().flatten().any(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: "new landmark covariance",
            value: f64::NAN,
        });
    }
    // Grow: insert 3 rows and columns at c0 (before the camera block).
    let n2 = n + LANDMARK_DIM;
    let mut p2 = DMatrix::<f64>::zeros(n2, n2);
    let old = p.as_slice();
    let new = p2.as_mut_slice();
    for j2 in 0..n2 {
        let dst = &mut new[at(n2, 0, j2)..at(n2, 0, j2 + 1)];
        if (c0..c0 + LANDMARK_DIM).contains(&j2) {
            let a = j2 - c0;
            dst[..c0].copy_from_slice(&cross[a][..c0]);
            for b in 0..LANDMARK_DIM {
                dst[c0 + b] = pll[(b, a)];
            }
            dst[c0 + LANDMARK_DIM..].copy_from_slice(&cross[a][c0..]);
        } else {
            let j = if j2 < c0 { j2 } else { j2 - LANDMARK_DIM };
            let src = &old[at(n, 0, j)..at(n, 0, j + 1)];
            dst[..c0].copy_from_slice(&src[..c0]);
            for b in 0..LANDMARK_DIM {
                dst[c0 + b] = cross[b][j];
            }
            dst[c0 + LANDMARK_DIM..].copy_from_slice(&src[c0..]);
        }
    }
    Ok(p2)
}

/// `p` (`n x n`) without the rows and columns `li..li + 3`.
fn shrink(p: &DMatrix<f64>, li: usize) -> DMatrix<f64> {
    let n = p.nrows();
    let n2 = n - LANDMARK_DIM;
    let keep = |i: usize| if i < li { i } else { i + LANDMARK_DIM };
    let mut p2 = DMatrix::<f64>::zeros(n2, n2);
    let old = p.as_slice();
    let new = p2.as_mut_slice();
    for j2 in 0..n2 {
        let src = &old[at(n, 0, keep(j2))..at(n, 0, keep(j2) + 1)];
        let dst = &mut new[at(n2, 0, j2)..at(n2, 0, j2 + 1)];
        dst[..li].copy_from_slice(&src[..li]);
        dst[li..].copy_from_slice(&src[li + LANDMARK_DIM..]);
    }
    p2
}

/// Two landmarks compared ([`Ekf::landmark_pair_distance`], [`Ekf::merge_landmarks`]).
struct PairDifference {
    /// The state index of the first landmark's x.
    ia: usize,
    /// The state index of the second's.
    ib: usize,
    /// `x_a - x_b`.
    d: Vector3<f64>,
    /// Its covariance `S`.
    s: Matrix3<f64>,
    /// The squared Mahalanobis distance `d^T S^-1 d`.
    d2: f64,
}

/// `d world / d (x, y, theta)` of a point held fixed relative to the vehicle at `pose`, now at
/// `world`: it moves with the pose's position and turns about it with its heading.
pub(crate) fn carried_by_pose(pose: &rig_model::Pose2, world: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(
        1.0,
        0.0,
        -(world.y - pose.y),
        0.0,
        1.0,
        world.x - pose.x,
        0.0,
        0.0,
        0.0,
    )
}

/// `P <- T P T^T` on the lower triangle of the symmetric `n x n` buffer `p`, with
/// `T = D + sum_s a_s e_s^T` the identity but for the three `targets` rows (row `targets[r]`
/// scaled by `scale[r]`, plus `a_s[r]` times source row `s`, for every `(s, a_s)` of
/// `sources`; no source is a target). All sources at once: each row is read once and each
/// target row written once (one source at a time read and wrote the three target rows for
/// each, a tenth of a dense hall's replay).
pub(crate) fn shear_rows(
    p: &mut [f64],
    n: usize,
    targets: [usize; 3],
    scale: [f64; 3],
    sources: &[(usize, [f64; 3])],
) {
    use crate::linalg::sym;
    use crate::state::at;
    // D = A R: row r is sum_s a_s[r] (row s of P).
    let mut d = [
        alloc::vec![0.0; n],
        alloc::vec![0.0; n],
        alloc::vec![0.0; n],
    ];
    for &(src, a) in sources {
        for j in 0..n {
            let v = sym(p, n, src, j);
            for (dr, ar) in d.iter_mut().zip(a) {
                if let Some(x) = dr.get_mut(j) {
                    *x += ar * v;
                }
            }
        }
    }
    let old: [Vec<f64>; 3] = targets.map(|t| (0..n).map(|j| sym(p, n, t, j)).collect());
    let get = |v: &[f64], j: usize| v.get(j).copied().unwrap_or(f64::NAN);
    for (r, &t) in targets.iter().enumerate() {
        for j in 0..n {
            let v = match targets.iter().position(|&u| u == j) {
                // Both ends targets: d_t d_u P_tu + d_u (A R)_tu + d_t (A R)_ut
                // + (A P_SS A^T)_tu.
                Some(q) => {
                    let mut v = scale[r] * scale[q] * get(&old[r], j) + scale[q] * get(&d[r], j);
                    v += scale[r] * get(&d[q], t);
                    for &(src, a) in sources {
                        v += a[r] * get(&d[q], src);
                    }
                    v
                }
                None => scale[r] * get(&old[r], j) + get(&d[r], j),
            };
            let (row, col) = if t >= j { (t, j) } else { (j, t) };
            if let Some(x) = p.get_mut(at(n, row, col)) {
                *x = v;
            }
        }
    }
}
