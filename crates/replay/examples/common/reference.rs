//! The batch reference of `batch_reference` and `hall_mc` (issue 35, items 4 and 6): the
//! frames a replay decoded, solved as one batch (every pose, lamp and estimated camera
//! parameter at once, Levenberg-Marquardt on every frame's pixels and the odometry,
//! `selfcal::smoother` never handing over) with the association taken from the simulator's
//! truth: each feature it made of a lamp is that lamp's observation, clutter is left out.
//! What the navigator's map is measured against: how close it comes to what the data allow.

use std::collections::BTreeSet;

use rig_model::handover::BatchHandover;
use selfcal::smoother::{Smoother, SmootherSettings};
use vslam_ekf::Increment;

/// Solves the batch over the frames of `run` whose times are in `decoded`, solving every
/// `solve_every` frames and at the end. `None` without a frame.
pub(crate) fn solve(
    rig: &rig_model::Rig,
    run: &sim::SimRun,
    decoded: &BTreeSet<u64>,
    solve_every: usize,
) -> Option<BatchHandover> {
    let settings = SmootherSettings {
        max_frames: usize::MAX,
        solve_every,
        consecutive: usize::MAX,
        // Every lamp: the default budget (48) would compare the navigator's whole map with
        // the reference's first 48 lamps.
        max_landmarks: usize::MAX,
        max_in_view: usize::MAX,
        // Every estimated parameter kept at the hand-over (none held at nominal as
        // uninformed): the reference is what the whole drive says of each.
        sigma_fraction: 1.0,
        // The association is the truth's: a new lamp is never bound to another's landmark.
        rebind_px: 0.0,
        ..SmootherSettings::default()
    };
    let mut batch = Smoother::new(rig.clone(), settings);
    let samples = &run.odometry;
    let mut previous: Option<u64> = None;
    for f in run.frames.iter().filter(|f| decoded.contains(&f.t_us)) {
        let vehicle = rig.nominal.vehicle;
        let odometry = previous.and_then(|t0| {
            Increment::from_odometry_vehicle(samples, t0, f.t_us, &rig.noise, &vehicle, true)
                .ok()
                .map(|(inc, reported, jv)| rig_model::odometry::OdometryFactor {
                    motion: inc.motion,
                    covariance: reported,
                    vehicle,
                    vehicle_jacobian: jv,
                    frames_us: (t0, f.t_us),
                    samples: {
                        let from = t0.saturating_sub(200_000);
                        let a = samples
                            .partition_point(|s| s.t_us <= from)
                            .saturating_sub(1);
                        let b = samples.partition_point(|s| s.t_us <= f.t_us + 200_000);
                        samples.get(a..b).map(<[_]>::to_vec).unwrap_or_default()
                    },
                })
        });
        previous = Some(f.t_us);
        let mut observations = Vec::new();
        for v in &f.views {
            let left = f.left.features.iter().find(|x| x.lamp == Some(v.id));
            let right = f.right.features.iter().find(|x| x.lamp == Some(v.id));
            let (Some(a), Some(b)) = (left, right) else {
                continue;
            };
            let (a, b) = (a.feature(), b.feature());
            let (mut l, mut r) = (
                nalgebra::Vector2::new(a.u(), a.v()),
                nalgebra::Vector2::new(b.u(), b.v()),
            );
            // The board's features are raw pixels: through real lenses, into the rectified
            // camera the batch models (vehicle-interfaces.md 1.1).
            if let Some(lens) = &rig.lens {
                let c = &rig.nominal;
                let (Some(lr), Some(rr)) = (
                    lens.left.rectify_point(l, c.f, c.cx, c.cy),
                    lens.right.rectify_point(r, c.f, c.cx, c.cy),
                ) else {
                    continue;
                };
                (l, r) = (lr, rr);
            }
            observations.push((
                u64::from(v.id),
                rig_model::Measurement::new(l.x, l.y, r.x, r.y),
            ));
        }
        batch.add_frame(f.t_us, odometry, &observations, &[]);
    }
    batch.finish().cloned()
}

/// The lamp a reference landmark is (its track is the lamp's id: the truth's association).
pub(crate) fn lamp_of<'a>(
    landmark: &rig_model::handover::BatchLandmark,
    run: &'a sim::SimRun,
) -> Option<&'a sim::Lamp> {
    run.landmarks
        .iter()
        .find(|lamp| u64::from(lamp.id) == landmark.track)
}

/// The reference's landmark RMS against the truth, metres, and the landmarks it held (each
/// is its lamp: the association is the truth's).
pub(crate) fn landmark_rms(handover: &BatchHandover, run: &sim::SimRun) -> (f64, usize) {
    let (mut sq, mut n) = (0.0, 0usize);
    for l in &handover.landmarks {
        if let Some(lamp) = lamp_of(l, run) {
            sq += (lamp.position - l.position).norm_squared();
            n += 1;
        }
    }
    #[allow(clippy::cast_precision_loss)]
    let rms = (sq / n.max(1) as f64).sqrt();
    (rms, n)
}
