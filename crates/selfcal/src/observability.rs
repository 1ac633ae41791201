//! The observability analysis of the frame-pair solver: what the data say about each
//! estimated parameter compared with its prior, and the known traps of the rig and the path
//! ([`structural_trap`]) that make a parameter unobservable whatever the amount of data.
//!
//! A parameter the data cannot constrain is held at its nominal value and reported with the
//! reason (the known traps: an upward-looking camera on planar motion cannot give `f`; planar
//! motion never gives the camera height; a straight path cannot give the mounting offsets or
//! the roll).

use alloc::vec::Vec;

use nalgebra::DMatrix;

use rig_model::camera::{CameraParams, Param};
use rig_model::config::Rig;
use rig_model::handover::{FramePair, Mat10, ObservabilityReport, ParamObservability};

use crate::solve::{SolverSettings, estimated_mask, prior_precision};
use crate::step::covariance;

/// The known trap of the rig and the path that makes `p` unobservable, if any: an upward head
/// (`tilted` false) for `f`, planar motion for the camera height, a straight path
/// (`total_rotation_rad`, the sum of the odometry's absolute yaw changes, under 0.3 rad) for
/// the mounting offsets and angles and the odometry's yaw scale, and a path without changes
/// of speed or heading (`speed_change_mps`, the sum of the absolute changes of speed between
/// frames, under 0.2 m/s, and no turn) for the clock offset (vehicle-interfaces.md 1.2).
/// Anything else is a lack of data so far.
pub fn structural_trap(
    p: Param,
    tilted: bool,
    total_rotation_rad: f64,
    speed_change_mps: f64,
) -> Option<&'static str> {
    match p {
        Param::OdomYawScale if total_rotation_rad < 0.3 => Some(
            "the odometry's yaw scale needs turns: on a straight path the yaw rate is zero whatever its scale",
        ),
        Param::TimeOffset if total_rotation_rad < 0.3 && speed_change_mps < 0.2 => Some(
            "the clock offset needs changes of speed or heading: at a constant velocity it only shifts the path",
        ),
        Param::F if !tilted => Some(
            "with the camera looking straight up and planar motion, f and every landmark depth scale together: f is not observable unless the camera is tilted or a lamp height is known",
        ),
        Param::MountZ => Some(
            "the camera height is not observable from planar motion: it cancels between the two instants",
        ),
        Param::MountX | Param::MountY | Param::MountYaw if total_rotation_rad < 0.3 => Some(
            "a straight path cannot give the mounting offsets: they cancel unless the vehicle turns",
        ),
        Param::MountRoll | Param::MountPitch if total_rotation_rad < 0.3 => Some(
            "a straight path cannot give the roll about the direction of travel: the vehicle must turn",
        ),
        _ => None,
    }
}

/// Observability of the estimated parameters from the data's information matrix `h_data`
/// (`J^T W J` of eq. (2)), the frame pairs' path and the camera `c`.
pub(crate) fn observability(
    h_data: &Mat10,
    rig: &Rig,
    pairs: &[FramePair],
    c: &CameraParams,
    settings: &SolverSettings,
) -> ObservabilityReport {
    let estimated = estimated_mask(rig);
    let prior = prior_precision(rig, &estimated);
    let posterior = covariance(&(h_data + Mat10::from_diagonal(&prior)), &estimated);
    let total_rotation: f64 = pairs.iter().map(|p| libm::fabs(p.motion.dtheta)).sum();
    let tilted = c.mount.is_tilted();
    let mut report = ObservabilityReport::default();
    // Information in prior-sigma units: S H S with S = diag(prior sigma).
    let mut scaled = Mat10::identity();
    let idx: Vec<usize> = rig.estimate.iter().map(|p| p.index()).collect();
    for &i in &idx {
        for &j in &idx {
            let (si, sj) = (rig.prior[i].unwrap_or(1.0), rig.prior[j].unwrap_or(1.0));
            scaled[(i, j)] = h_data[(i, j)] * si * sj;
        }
    }
    let sub = DMatrix::from_fn(idx.len(), idx.len(), |a, b| scaled[(idx[a], idx[b])]);
    let mut eig: Vec<f64> = sub.symmetric_eigenvalues().iter().copied().collect();
    eig.sort_by(f64::total_cmp);
    report.information_eigenvalues = eig;
    for p in &rig.estimate {
        let i = p.index();
        let prior_sigma = rig.prior[i].unwrap_or(f64::INFINITY);
        let posterior_sigma = libm::sqrt(posterior[(i, i)].max(0.0));
        let info = h_data[(i, i)];
        let data_sigma = if info > 0.0 {
            1.0 / libm::sqrt(info)
        } else {
            f64::INFINITY
        };
        let observable = posterior_sigma <= settings.observable_ratio * prior_sigma;
        // The known traps are properties of the rig and the path; anything else is a lack of
        // data so far, which more driving may cure.
        // The pair solver does not model V (its motions are fixed): no speed term.
        let trap = structural_trap(*p, tilted, total_rotation, f64::INFINITY);
        let reason = (!observable).then_some(trap.unwrap_or(
            "the data so far constrain it less than its prior: more motion (turns, speed) or more landmarks are needed",
        ));
        let structural = !observable && trap.is_some();
        report.params.push(ParamObservability {
            param: *p,
            prior_sigma,
            data_sigma,
            posterior_sigma,
            observable,
            reason,
            structural,
        });
    }
    let obs: Vec<usize> = report
        .params
        .iter()
        .filter(|p| p.observable)
        .map(|p| p.param.index())
        .collect();
    for (a, &i) in obs.iter().enumerate() {
        for &j in obs.iter().skip(a + 1) {
            let denom = libm::sqrt(posterior[(i, i)] * posterior[(j, j)]);
            if denom > 0.0 {
                let r = posterior[(i, j)] / denom;
                if report
                    .max_correlation
                    .is_none_or(|(_, _, m)| libm::fabs(r) > libm::fabs(m))
                {
                    report.max_correlation = Some((Param::ALL[i], Param::ALL[j], r));
                }
            }
        }
    }
    report
}
