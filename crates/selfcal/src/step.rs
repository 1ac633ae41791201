//! eq. (2), the Levenberg-Marquardt step of the frame-pair solver, and the linear algebra of
//! its normal equations (restricted to the parameters being estimated).

// Loops over the ten parameter indices address several arrays at once.
#![allow(clippy::needless_range_loop)]

use rig_model::camera::{N_PARAMS, ParamVector};
use rig_model::handover::Mat10;

/// eq. (2): the Levenberg-Marquardt step `dC = -(J^T W J + k D)^-1 J^T W E_L`.
///
/// `h` is `J^T W J` and `g` is `J^T W E_L` (with the prior's terms added: the paper has
/// neither prior nor robust weights, `W = I`, and `E_L` of the opposite sign, hence its `+`),
/// `lambda` is the damping `k`, and `D = diag(h)` (each entry at least `1e-12`, so that a
/// parameter the data do not inform is still damped). Only the `active` parameters move: the
/// others' rows and columns are replaced by the identity and their step is zero. `None` when
/// the damped system is not positive definite (the caller raises `k`).
pub fn levenberg_marquardt_step(
    h: &Mat10,
    g: &ParamVector,
    lambda: f64,
    active: &[bool; N_PARAMS],
) -> Option<ParamVector> {
    let mut damped = *h;
    for i in 0..N_PARAMS {
        damped[(i, i)] += lambda * h[(i, i)].max(1e-12);
    }
    let ch = masked(&damped, active).cholesky()?;
    let mut step = -ch.solve(g);
    for i in 0..N_PARAMS {
        if !active[i] {
            step[i] = 0.0;
        }
    }
    Some(step)
}

/// Restricts a 10x10 system to `active` parameters: inactive rows and columns become the
/// identity, so that their step is zero.
pub(crate) fn masked(h: &Mat10, active: &[bool; N_PARAMS]) -> Mat10 {
    let mut m = *h;
    for i in 0..N_PARAMS {
        if !active[i] {
            m.row_mut(i).fill(0.0);
            m.column_mut(i).fill(0.0);
            m[(i, i)] = 1.0;
        }
    }
    m
}

/// Inverse of `h` over the `active` parameters, zero rows and columns for the others (zero
/// when `h` is not positive definite there).
pub(crate) fn covariance(h: &Mat10, active: &[bool; N_PARAMS]) -> Mat10 {
    let mut cov = masked(h, active)
        .cholesky()
        .map_or_else(Mat10::zeros, |ch| ch.inverse());
    for i in 0..N_PARAMS {
        if !active[i] {
            cov.row_mut(i).fill(0.0);
            cov.column_mut(i).fill(0.0);
        }
    }
    cov
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    /// The step solves the damped normal equations over the active parameters and leaves the
    /// others where they are.
    #[test]
    fn the_step_solves_the_damped_normal_equations() {
        let b = Mat10::from_fn(|i, j| {
            #[allow(clippy::cast_precision_loss)]
            let (i, j) = (i as f64, j as f64);
            libm::sin(1.1 * i + 0.3 * j * j + 0.5)
        });
        let h = b * b.transpose() + Mat10::identity() * 0.1;
        let g = ParamVector::from_fn(|i, _| {
            #[allow(clippy::cast_precision_loss)]
            let i = i as f64;
            libm::cos(0.7 * i)
        });
        let mut active = [true; N_PARAMS];
        active[4] = false;
        active[7] = false;
        let lambda = 0.01;
        let step = levenberg_marquardt_step(&h, &g, lambda, &active).expect("positive definite");
        let idx: Vec<usize> = (0..N_PARAMS).filter(|&i| active[i]).collect();
        let n = idx.len();
        let a = nalgebra::DMatrix::from_fn(n, n, |r, c| {
            let (i, j) = (idx[r], idx[c]);
            h[(i, j)] + if i == j { lambda * h[(i, i)] } else { 0.0 }
        });
        let rhs = nalgebra::DVector::from_fn(n, |r, _| -g[idx[r]]);
        let expected = a.try_inverse().unwrap() * rhs;
        for (r, &i) in idx.iter().enumerate() {
            assert!(
                (step[i] - expected[r]).abs() <= 1e-9 * expected.norm(),
                "{i}"
            );
        }
        assert_eq!((step[4], step[7]), (0.0, 0.0));
        let indefinite = -Mat10::identity();
        assert!(levenberg_marquardt_step(&indefinite, &g, lambda, &active).is_none());
    }
}
