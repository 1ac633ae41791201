//! The map's metric scale: each update's correction of the pose and of the odometry's scale
//! taken in units of the baseline.
//!
//! The pixels fix every length in units of the baseline `B`, and the odometry fixes
//! `odom_scale x` lengths in metres (reported = `odom_scale` x true); what sets the metric
//! scale is the rig's small lever arm, so the direction "every length and `B` up by a factor,
//! the odometry's scale down by it" is nearly unobservable. Its Jacobian in metric
//! coordinates depends on the estimate (`d X / d B = X / B`, `d s / d B = -s / B`), and a
//! filter that adds its linear corrections in metres moves its linearisation point along that
//! direction without the covariance: the baseline then drifts several of its prior sigmas in
//! minutes of driving while its sigma stays, and every depth comes out long by as much
//! (docs/vehicle.md, "Where the bias is"; the toy filter `scripts/scale_drift_toy.py`
//! reproduces it, +3.8 prior sigmas in five minutes on four seeds).
//!
//! The cure is the filter in units of the baseline, `X' = X / B`, `s' = s B` (the toy: +0.007).
//! Every prediction is the same in either coordinate (the prediction is linear in the pose,
//! and its Jacobians are the chain rule's); only the update's linear correction differs. So
//! the filter keeps metres and, after each update, re-applies the correction in baseline units
//! and maps it back ([`Ekf::follow_scale`]): the mean by the exact map, the covariance by
//! `M = T_back(new) T_fwd(old)`, `T_fwd` the Jacobian of `(X / B, s B)` at the point before
//! the update and `T_back` its inverse at the point after it. `M` is the identity but for the
//! pose's `X, Y` rows and the odometry scale's row: a scale `D` and a column `a` in the
//! baseline's, `M = D + a e_B^T`, O(n) rows of `P` (`Ekf::transform_target_rows`, the
//! landmarks' shears' transform, dense or in a local session). The landmarks take their share through
//! their placements (`Ekf::shear_linearisation_point`: the baseline's column `(L - C) / B` of
//! a landmark follows its estimate); the toy ends at +0.13 with the pose and the scale alone.

use rig_model::camera::Param;

use crate::filter::Ekf;

/// The estimate the update started from, for [`Ekf::follow_scale`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct ScalePoint {
    /// The pose's `X, Y`, metres.
    position: [f64; 2],
    /// The baseline's state index and value.
    baseline: (usize, f64),
    /// The odometry scale's state index and value, when it is estimated.
    odom_scale: Option<(usize, f64)>,
}

impl Ekf {
    /// The point [`Ekf::follow_scale`] maps from: `None` when it does nothing (the setting
    /// off, the baseline not estimated or held, the pose lost).
    pub(crate) fn scale_point(&self) -> Option<ScalePoint> {
        if !self.settings.follow_scale || self.pose_lost() {
            return None;
        }
        let c0 = self.camera_offset();
        let index = |param: Param| {
            let k = self.estimated.iter().position(|&p| p == param)?;
            let held = self.held.get(param.index()).copied().unwrap_or(false);
            (!held && self.settings.camera_update != crate::CameraUpdate::Consider)
                .then_some(c0 + k)
        };
        let kb = index(Param::Baseline)?;
        let b = self.x.get(kb).copied()?;
        let odom_scale = index(Param::OdomScale).and_then(|k| Some((k, self.x.get(k).copied()?)));
        (b.is_finite() && b > 0.0).then_some(ScalePoint {
            position: [self.x[0], self.x[1]],
            baseline: (kb, b),
            odom_scale,
        })
    }

    /// The update's correction since `from`, re-applied in units of the baseline (module
    /// docs): the pose's `X, Y` and the odometry scale set by the exact map, `P <- M P M^T`.
    /// Nothing changes when the baseline did not stay finite and positive.
    pub(crate) fn follow_scale(&mut self, from: &ScalePoint) {
        let (kb, b0) = from.baseline;
        let Some(&b1) = self.x.get(kb) else { return };
        if !(b1.is_finite() && b1 > 0.0) {
            return;
        }
        let db = b1 - b0;
        // M = D + a e_B^T on the rows of X, Y and the odometry scale (the heading's, with
        // d = 1 and a = 0, when the scale is not estimated).
        let (mut rows, mut d, mut a) = ([0, 1, 2], [1.0; 3], [0.0; 3]);
        for r in 0..2 {
            // X' = X / B: the old point, and the linear correction in those units.
            let x0 = from.position[r] / b0;
            let x1 = x0 + (self.x[r] - from.position[r]) / b0 - x0 * db / b0;
            self.x[r] = b1 * x1;
            d[r] = b1 / b0;
            a[r] = x1 - b1 * x0 / b0;
        }
        if let Some((ks, s0)) = from.odom_scale
            && let Some(&s) = self.x.get(ks)
        {
            // s' = s B, corrected linearly; s = s' / B at the new point.
            let s1 = s0 * b0 + b0 * (s - s0) + s0 * db;
            self.x[ks] = s1 / b1;
            rows[2] = ks;
            d[2] = b0 / b1;
            a[2] = s0 / b1 - s1 / (b1 * b1);
        }
        if d == [1.0; 3] && a == [0.0; 3] {
            return;
        }
        // The pose and the camera are always active in a session: it is always applied.
        self.transform_target_rows(rows, d, &[(kb, a)]);
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use alloc::vec::Vec;
    use nalgebra::{DMatrix, Matrix4, Vector3};
    use rig_model::Pose2;

    use super::*;
    use crate::{LandmarkId, Settings};

    /// A filter estimating the baseline and the odometry scale, driven a few steps past
    /// twelve lamps, so that `P` correlates the pose, the baseline and the scale.
    fn driven() -> Ekf {
        let rig = crate::filter::tests::rig_estimating(&[
            (Param::Baseline, 0.005),
            (Param::OdomScale, 0.02),
        ]);
        let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
        let mut noise = crate::local::tests::Lcg(3);
        let lamps: Vec<Vector3<f64>> = (0..12)
            .map(|k| Vector3::new(f64::from(k % 4) * 0.4, f64::from(k / 4) * 0.4 - 0.4, 2.5))
            .collect();
        let mut measure = |pose: &Pose2, p: &Vector3<f64>| {
            let mut z = rig_model::project(&rig.nominal, pose, p).unwrap();
            for v in z.iter_mut() {
                *v += noise.next();
            }
            z
        };
        let ids: Vec<LandmarkId> = lamps
            .iter()
            .map(|p| ekf.add_landmark(&measure(&Pose2::default(), p)).unwrap())
            .collect();
        let mut truth = Pose2::default();
        for _ in 0..5 {
            ekf.predict(0.5, 0.0, 0.01, 0.1).unwrap();
            truth = Pose2::new(truth.x + 0.05, truth.y, truth.theta + 0.001);
            let batch: Vec<_> = ids
                .iter()
                .zip(&lamps)
                .map(|(id, p)| (*id, measure(&truth, p)))
                .collect();
            ekf.update(&batch).unwrap();
        }
        ekf
    }

    /// The correction re-applied in units of the baseline: `X / B` and `s B` end at the old
    /// point plus the linear correction in those units, and `P` at `M P M^T` with
    /// `M = T_back(new) T_fwd(old)`, both Jacobians of the coordinate maps written out here.
    #[test]
    fn the_correction_is_taken_in_units_of_the_baseline() {
        let mut ekf = driven();
        let from = ekf.scale_point().expect("the baseline is estimated");
        let kb = ekf.camera_state_index(Param::Baseline).unwrap();
        let ks = ekf.camera_state_index(Param::OdomScale).unwrap();
        let before = ekf.state().clone();
        // An update's correction, as the filter adds it in metres.
        let dx = [0.03, -0.02, 0.0];
        let (db, ds) = (4e-4, -3e-3);
        for (r, d) in dx.iter().enumerate() {
            ekf.x[r] += d;
        }
        ekf.x[kb] += db;
        ekf.x[ks] += ds;
        let p = ekf.covariance();
        ekf.follow_scale(&from);
        let x = ekf.state();
        let (b0, s0) = (before[kb], before[ks]);
        let b1 = x[kb];
        assert!(
            (b1 - (b0 + db)).abs() < 1e-15,
            "the baseline itself moves as corrected"
        );
        for r in 0..2 {
            let want = before[r] / b0 + dx[r] / b0 - before[r] * db / (b0 * b0);
            assert!((x[r] / b1 - want).abs() < 1e-12, "row {r}");
        }
        assert!((x[ks] * b1 - (s0 * b0 + b0 * ds + s0 * db)).abs() < 1e-12);
        // Over (X, Y, s, B): T_fwd = d(X / B, Y / B, s B, B) at the old point, T_back =
        // d(X' B, Y' B, s' / B, B) at the new one in units of the baseline.
        let t_fwd = Matrix4::new(
            1.0 / b0,
            0.0,
            0.0,
            -before[0] / (b0 * b0),
            0.0,
            1.0 / b0,
            0.0,
            -before[1] / (b0 * b0),
            0.0,
            0.0,
            b0,
            s0,
            0.0,
            0.0,
            0.0,
            1.0,
        );
        let (xb, yb, sb) = (x[0] / b1, x[1] / b1, x[ks] * b1);
        let t_back = Matrix4::new(
            b1,
            0.0,
            0.0,
            xb,
            0.0,
            b1,
            0.0,
            yb,
            0.0,
            0.0,
            1.0 / b1,
            -sb / (b1 * b1),
            0.0,
            0.0,
            0.0,
            1.0,
        );
        let m4 = t_back * t_fwd;
        let n = p.nrows();
        let mut m = DMatrix::<f64>::identity(n, n);
        let idx = [0, 1, ks, kb];
        for (i, &a) in idx.iter().enumerate() {
            for (j, &b) in idx.iter().enumerate() {
                m[(a, b)] = m4[(i, j)];
            }
        }
        let want = &m * &p * m.transpose();
        let got = ekf.covariance();
        let off = (&got - &want).amax() / want.amax();
        assert!(off < 1e-12, "covariance off by {off} (relative)");
        assert!((&got - &p).amax() > 0.0, "the covariance did not change");
    }

    /// The rows' transform (`crate::landmarks::shear_rows`) with a scale on each target row:
    /// `M P M^T` for `M = D + a e_B^T`.
    #[test]
    fn the_row_transform_is_m_p_m_transposed() {
        let n = 7;
        let a = DMatrix::<f64>::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 11) as f64 / 5.0 - 1.0);
        let p = &a * a.transpose() + DMatrix::<f64>::identity(n, n);
        let (rows, d, col, kb) = ([0, 1, 5], [1.01, 0.99, 0.97], [0.3, -0.2, 0.5], 4);
        let mut m = DMatrix::<f64>::identity(n, n);
        for q in 0..3 {
            m[(rows[q], rows[q])] = d[q];
            m[(rows[q], kb)] = col[q];
        }
        let want = &m * &p * m.transpose();
        let mut got = p.clone();
        crate::landmarks::shear_rows(got.as_mut_slice(), n, rows, d, &[(kb, col)]);
        for j in 0..n {
            for i in j..n {
                assert!(
                    (got[(i, j)] - want[(i, j)]).abs() < 1e-12,
                    "({i}, {j}): {} against {}",
                    got[(i, j)],
                    want[(i, j)]
                );
            }
        }
    }
}
