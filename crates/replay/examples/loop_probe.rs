//! Which lamp each observation really was (issue 35, loops): the navigator run over a
//! simulator log frame by frame; every feature the update used is named by the true lamp
//! nearest to it (the log's truth pose, camera and lamps, through the lens), each landmark by
//! the lamp of its first observation, and every frame where an observation's lamp is not its
//! landmark's (a wrong association), where map matching bound a track, or where the pose moved
//! by more than `JUMP_M`, is printed with the pose error and sigma.
//!
//! `cargo run --release -p replay --example loop_probe -- LOG.mcap [FROM_S TO_S] [--vehicle]
//! [--no-smoother] [--fej-pose] [--fej-always | --no-fej-prediction] [--error-states] [--velocity-states] [--relative-lost] [--rig RIG.toml] [--field DEG] [--max-in-view N] [--missed [--worst N]] [--lamp ID]
//! [--nees-at T_S [--worst N]] [--cov-at T_S] [--partial-from T_S]`:
//! `--vehicle` also prints the vehicle's parameters, their sigmas and their correlations with
//! the pose at every printed frame; `--no-smoother` runs phase 2 without the fixed-lag
//! smoother; `--rig` runs on that rig instead of the log's; `--field` and `--max-in-view` set
//! the navigator's field of use and its cap on landmarks in view; `--missed` reports, per lamp
//! in view 20 frames or more that no landmark is, where its observations were lost, and the
//! landmarks farthest from their lamps (12, or `--worst N`) with the error's vector, the
//! landmark's sigmas and where the lamp is (a map off by its scale shows as errors growing
//! with the distance from the first frame, inside their sigmas); `--lamp`
//! follows one lamp's stereo match and track while it is in view; `--nees-at T` prints the
//! map's NEES and its widest common modes at `T` seconds ([`print_map_nees`]), and with
//! `--worst N` the `N` landmarks that add the most to it (a landmark off relative to the others
//! it is correlated with shows there even when its own sigmas cover its error); `--cov-at T`
//! prints, every frame for half a second from `T` seconds, the covariance's structure
//! ([`print_cov`]: the heading's sigma given the map, the common turn of the landmarks near
//! the vehicle, and every twin pair's difference against the heading) and, at phase 1's
//! hand-over, each landmark handed over with when it was first seen; `--partial-from T`
//! prints every frame from `T` seconds the information on turning the pose and the
//! landmarks newer than `T` together ([`print_partial`]; the landmarks at their
//! linearisation points, at their estimates with `PROBE_EST` set, the pose and the lamps at
//! the truth with `PROBE_TRUE`). With `PROBE_ACC` set, every printed frame lists the
//! landmarks the update accepted with their linearisation point's distance from the
//! estimate. Every 100th frame is printed too (the drift in between).
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::collections::BTreeMap;
use std::process::ExitCode;

use nalgebra::{Vector2, Vector3};
use nav::{NavSettings, Navigator};
use rig_model::Pose2;
use vehicle_log::Record;

/// A pose change this large in one frame is printed, metres.
const JUMP_M: f64 = 0.2;
/// A feature farther than this from every lamp's raw pixel is clutter, pixels.
const LAMP_PX: f64 = 3.0;

/// The covariance's structure at one frame (`--cov-at T`, every frame for half a second):
/// the pose's sigmas; the heading's sigma given every landmark's horizontal position (how
/// well the pose's heading is known relative to the map); the sigma of the common turn of
/// the landmarks within 20 m about their centroid (how well the map's block is known against
/// the first frame's world); and for every pair of landmarks closer than 0.1 m (twins the
/// merge guard may join), the share of the heading's variance their difference explains and,
/// along each principal direction of the difference, its sigma and correlation with the
/// heading.
fn print_cov(t_s: f64, ekf: &vslam_ekf::Ekf) {
    let p = ekf.covariance();
    let pose = ekf.pose();
    let ls: Vec<(vslam_ekf::LandmarkId, Vector3<f64>, usize)> = ekf
        .landmarks()
        .filter_map(|l| Some((l.id, l.position, ekf.landmark_state_index(l.id)?)))
        .collect();
    let idx: Vec<usize> = ls.iter().flat_map(|&(_, _, i)| [i, i + 1]).collect();
    let k = idx.len();
    let pll = nalgebra::DMatrix::from_fn(k, k, |a, b| p[(idx[a], idx[b])]);
    let ptl = nalgebra::DMatrix::from_fn(1, k, |_, b| p[(2, idx[b])]);
    let cond = pll.clone().cholesky().map(|c| {
        let x = c.solve(&ptl.transpose());
        (p[(2, 2)] - (&ptl * x)[(0, 0)]).max(0.0).sqrt()
    });
    // The common turn of the block about its centroid, least squares over the landmarks.
    let near: Vec<usize> = (0..ls.len())
        .filter(|&j| (ls[j].1.x - pose.x).hypot(ls[j].1.y - pose.y) < 20.0)
        .collect();
    let mut turn = f64::NAN;
    if near.len() >= 2 {
        let (mut cx, mut cy) = (0.0, 0.0);
        for &j in &near {
            cx += ls[j].1.x;
            cy += ls[j].1.y;
        }
        cx /= near.len() as f64;
        cy /= near.len() as f64;
        let mut a = nalgebra::DVector::<f64>::zeros(k);
        let mut norm = 0.0;
        for &j in &near {
            let (dx, dy) = (ls[j].1.x - cx, ls[j].1.y - cy);
            a[2 * j] = -dy;
            a[2 * j + 1] = dx;
            norm += dx * dx + dy * dy;
        }
        a /= norm;
        turn = (a.transpose() * &pll * &a)[(0, 0)].max(0.0).sqrt();
    }
    println!(
        "  cov {t_s:.2}: pose sigma ({:.3} m, {:.3} m, {:.3} deg); heading given the map {}; the turn of {} landmarks within 20 m {:.3} deg",
        p[(0, 0)].sqrt(),
        p[(1, 1)].sqrt(),
        p[(2, 2)].sqrt().to_degrees(),
        cond.map_or("n/a".to_string(), |v| format!("{:.3} deg", v.to_degrees())),
        near.len(),
        turn.to_degrees(),
    );
    // The information along the world's unobservable motions (a turn about the origin, a
    // shift along x and along y): with a consistent filter it never grows.
    {
        let n = p.nrows();
        let mut dirs = [
            nalgebra::DVector::<f64>::zeros(n),
            nalgebra::DVector::<f64>::zeros(n),
            nalgebra::DVector::<f64>::zeros(n),
        ];
        dirs[0][0] = -pose.y;
        dirs[0][1] = pose.x;
        dirs[0][2] = 1.0;
        dirs[1][0] = 1.0;
        dirs[2][1] = 1.0;
        for &(_, pos, i) in &ls {
            dirs[0][i] = -pos.y;
            dirs[0][i + 1] = pos.x;
            dirs[1][i] = 1.0;
            dirs[2][i + 1] = 1.0;
        }
        match p.clone().cholesky() {
            Some(c) => {
                let s: Vec<f64> = dirs
                    .iter()
                    .map(|d| 1.0 / d.dot(&c.solve(d)).sqrt())
                    .collect();
                println!(
                    "  gauge {t_s:.2}: world turn sigma {:.4} deg, shift sigma x {:.4} m y {:.4} m",
                    s[0].to_degrees(),
                    s[1],
                    s[2]
                );
            }
            None => println!("  gauge {t_s:.2}: covariance not positive definite"),
        }
    }
    for a in 0..ls.len() {
        for b in a + 1..ls.len() {
            let (ia, ib) = (ls[a].2, ls[b].2);
            if (ls[a].1 - ls[b].1).norm() > 0.1 {
                continue;
            }
            let cov_t = |u: usize| p[(ia + u, 2)] - p[(ib + u, 2)];
            let sm = nalgebra::Matrix3::from_fn(|r, c| {
                p[(ia + r, ia + c)] + p[(ib + r, ib + c)]
                    - p[(ia + r, ib + c)]
                    - p[(ib + r, ia + c)]
            });
            let ct = Vector3::from_fn(|r, _| cov_t(r));
            let r2 = sm
                .cholesky()
                .map_or(f64::NAN, |c| ct.dot(&c.solve(&ct)) / p[(2, 2)]);
            println!(
                "    twins {:?} {:?}: the heading's share explained by their difference {r2:.3}",
                ls[a].0, ls[b].0
            );
            let e = sm.symmetric_eigen();
            for j in 0..3 {
                let v = e.eigenvectors.column(j);
                let sd = e.eigenvalues[j].max(0.0).sqrt();
                println!(
                    "      along ({:+.2}, {:+.2}, {:+.2}): sigma {:.4} m, correlation with the heading {:+.3}",
                    v[0],
                    v[1],
                    v[2],
                    sd,
                    v.dot(&ct) / (sd * p[(2, 2)].sqrt())
                );
            }
        }
    }
}

/// The information on turning the pose and every landmark newer than `id0` about `c`
/// (`--partial-from T`): while only those landmarks are seen it is unobservable, and with a
/// consistent filter its sigma never falls.
fn print_partial(
    t_s: f64,
    ekf: &vslam_ekf::Ekf,
    id0: u64,
    c: (f64, f64),
    truth: Option<(Pose2, &[vehicle_log::TruthLandmark])>,
) {
    let p = ekf.covariance();
    let n = p.nrows();
    let pose = truth.map_or(ekf.pose(), |(t, _)| t);
    let mut d = nalgebra::DVector::<f64>::zeros(n);
    d[0] = -(pose.y - c.1);
    d[1] = pose.x - c.0;
    d[2] = 1.0;
    let mut k = 0;
    // The first-estimates filter's unobservable turn has each landmark at its linearisation
    // point (the landmark's estimate where it has none).
    let fej = std::env::var("PROBE_EST").is_err();
    for l in ekf.landmarks() {
        if l.id.0 > id0
            && let Some(i) = ekf.landmark_state_index(l.id)
        {
            let nearest = truth.and_then(|(_, lamps)| {
                lamps.iter().min_by(|a, b| {
                    (a.x - l.position.x)
                        .hypot(a.y - l.position.y)
                        .total_cmp(&(b.x - l.position.x).hypot(b.y - l.position.y))
                })
            });
            let at = if let Some(t) = nearest {
                Vector3::new(t.x, t.y, t.z)
            } else if fej {
                ekf.linearisation_point(l.id).unwrap_or(l.position)
            } else {
                l.position
            };
            d[i] = -(at.y - c.1);
            d[i + 1] = at.x - c.0;
            k += 1;
        }
    }
    match p.clone().cholesky() {
        Some(ch) => println!(
            "  partial {t_s:.2}: turn of the pose and {k} new landmarks sigma {:.4} deg; heading sigma {:.4} deg",
            (1.0 / d.dot(&ch.solve(&d)).sqrt()).to_degrees(),
            p[(2, 2)].sqrt().to_degrees()
        ),
        None => println!("  partial {t_s:.2}: covariance not positive definite"),
    }
}

/// The map's consistency at one frame: the NEES of every landmark's horizontal position
/// jointly (each against the lamp nearest it, within 1.5 m) with the filter's joint
/// covariance, and the map's six widest common modes (eigenvectors of that covariance) with
/// the error along each in its sigmas: a map whose common modes (its shift and turn
/// against the first frame's world) have gained spurious information shows a NEES far above
/// its degrees of freedom and errors of many sigmas along its widest modes.
fn print_map_nees(
    t_s: f64,
    ekf: &vslam_ekf::Ekf,
    lamps: &[vehicle_log::TruthLandmark],
    worst: usize,
) {
    let p = ekf.covariance();
    let mut idx = Vec::new();
    let mut err = Vec::new();
    let mut ids = Vec::new();
    for (s, l) in ekf.landmarks().enumerate() {
        let pos = l.position;
        let near = lamps.iter().min_by(|a, b| {
            (a.x - pos.x)
                .hypot(a.y - pos.y)
                .total_cmp(&(b.x - pos.x).hypot(b.y - pos.y))
        });
        if let Some(n) = near
            && (n.x - pos.x).hypot(n.y - pos.y) < 1.5
        {
            let i = vslam_ekf::StateLayout::landmark(s);
            idx.extend([i, i + 1]);
            err.extend([pos.x - n.x, pos.y - n.y]);
            ids.push((l.id, pos));
        }
    }
    let k = idx.len();
    let sub = nalgebra::DMatrix::from_fn(k, k, |a, b| p[(idx[a], idx[b])]);
    let e = nalgebra::DVector::from_column_slice(&err);
    let nees = sub.clone().cholesky().map(|c| e.dot(&c.solve(&e)));
    let eig = sub.symmetric_eigen();
    let mut modes: Vec<(f64, f64)> = (0..k)
        .map(|j| {
            let s = eig.eigenvalues[j].max(1e-30).sqrt();
            (s, eig.eigenvectors.column(j).dot(&e) / s)
        })
        .collect();
    modes.sort_by(|a, b| b.0.total_cmp(&a.0));
    modes.truncate(6);
    let modes: Vec<String> = modes
        .iter()
        .map(|(s, e)| format!("{s:.3} m: {e:+.1} sigma"))
        .collect();
    println!(
        "map NEES at {t_s:.2} s: {} over {k} dof; widest modes {modes:?}",
        nees.map_or("not positive definite".to_string(), |v| format!("{v:.1}")),
    );
    let Some(total) = nees else {
        return;
    };
    // Each landmark's share: the NEES of the map less the NEES without it (2 dof each when
    // consistent).
    let mut shares: Vec<(f64, usize)> = (0..ids.len())
        .filter_map(|j| {
            let keep: Vec<usize> = (0..k).filter(|&a| a / 2 != j).collect();
            let sub = nalgebra::DMatrix::from_fn(keep.len(), keep.len(), |a, b| {
                p[(idx[keep[a]], idx[keep[b]])]
            });
            let e = nalgebra::DVector::from_fn(keep.len(), |a, _| err[keep[a]]);
            let without = sub.cholesky()?.solve(&e).dot(&e);
            Some((total - without, j))
        })
        .collect();
    shares.sort_by(|a, b| b.0.total_cmp(&a.0));
    for &(share, j) in shares.iter().take(worst) {
        let (id, pos) = ids[j];
        let (i, e) = (idx[2 * j], (err[2 * j], err[2 * j + 1]));
        println!(
            "  {id:?} at ({:+.2}, {:+.2}): adds {share:.1}; off ({:+.3}, {:+.3}) m, sigma ({:.3}, {:.3}) m",
            pos.x,
            pos.y,
            e.0,
            e.1,
            p[(i, i)].sqrt(),
            p[(i + 1, i + 1)].sqrt()
        );
    }
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("loop_probe: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The probe's options (see the module docs).
#[derive(Debug, Default)]
struct Options {
    vehicle: bool,
    no_smoother: bool,
    fej_pose: bool,
    fej_always: bool,
    no_fej_prediction: bool,
    error_states: bool,
    velocity_states: bool,
    relative_lost: bool,
    missed: bool,
    rig: Option<String>,
    field: Option<f64>,
    max_in_view: Option<usize>,
    lamp: Option<u32>,
    held_at: Option<f64>,
}

fn run() -> Result<(), String> {
    let usage = "usage: loop_probe LOG.mcap [FROM_S TO_S] [--vehicle] [--no-smoother] [--fej-pose] [--fej-always | --no-fej-prediction] [--error-states] [--velocity-states] [--relative-lost] [--rig RIG.toml] [--field DEG] [--max-in-view N] [--missed [--worst N]] [--lamp ID] [--held-at T_S] [--every-frame] [--nees-at T_S [--worst N]] [--cov-at T_S]";
    let mut opts = Options::default();
    let mut positional: Vec<String> = Vec::new();
    let mut every_frame = false;
    let mut nees_at: Option<f64> = None;
    let mut cov_at: Option<(f64, f64)> = None;
    let mut partial_from: Option<f64> = None;
    let mut partial: Option<(u64, (f64, f64))> = None;
    let mut worst: usize = 0;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value; {usage}"));
        match a.as_str() {
            "--vehicle" => opts.vehicle = true,
            "--no-smoother" => opts.no_smoother = true,
            "--fej-pose" => opts.fej_pose = true,
            "--fej-always" => opts.fej_always = true,
            "--no-fej-prediction" => opts.no_fej_prediction = true,
            "--error-states" => opts.error_states = true,
            "--velocity-states" => opts.velocity_states = true,
            "--relative-lost" => opts.relative_lost = true,
            "--missed" => opts.missed = true,
            "--every-frame" => every_frame = true,
            "--nees-at" => {
                nees_at = Some(
                    value("--nees-at")?
                        .parse()
                        .map_err(|e| format!("--nees-at: {e}"))?,
                );
            }
            "--partial-from" => {
                partial_from = Some(
                    value("--partial-from")?
                        .parse()
                        .map_err(|e| format!("--partial-from: {e}"))?,
                );
            }
            "--cov-at" => {
                let a: f64 = value("--cov-at")?
                    .parse()
                    .map_err(|e| format!("--cov-at: {e}"))?;
                cov_at = Some((a, a + 0.5));
            }
            "--worst" => {
                worst = value("--worst")?
                    .parse()
                    .map_err(|e| format!("--worst: {e}"))?;
            }
            "--rig" => opts.rig = Some(value("--rig")?),
            "--field" => {
                let v = value("--field")?;
                opts.field = Some(v.parse().map_err(|_| format!("--field {v:?}: {usage}"))?);
            }
            "--max-in-view" => {
                let v = value("--max-in-view")?;
                opts.max_in_view = Some(
                    v.parse()
                        .map_err(|_| format!("--max-in-view {v:?}: {usage}"))?,
                );
            }
            "--held-at" => {
                let v = value("--held-at")?;
                opts.held_at = Some(v.parse().map_err(|_| format!("--held-at {v:?}: {usage}"))?);
            }
            "--lamp" => {
                let v = value("--lamp")?;
                opts.lamp = Some(v.parse().map_err(|_| format!("--lamp {v:?}: {usage}"))?);
            }
            other if other.starts_with("--") => {
                return Err(format!("unknown option {other:?}; {usage}"));
            }
            _ => positional.push(a),
        }
    }
    let log = positional.first().ok_or(usage)?;
    let from: f64 = positional
        .get(1)
        .map_or(Ok(0.0), |s| s.parse())
        .map_err(|_| "FROM_S")?;
    let to: f64 = positional
        .get(2)
        .map_or(Ok(f64::MAX), |s| s.parse())
        .map_err(|_| "TO_S")?;
    let records = vehicle_log::read_log(log)
        .map_err(|e| e.to_string())?
        .records;
    let mut poses = BTreeMap::new();
    let mut lamps = Vec::new();
    let mut truth_camera = None;
    for r in records {
        match r {
            Record::TruthPose(p) => {
                poses.insert(p.t_us, Pose2::new(p.x, p.y, p.theta));
            }
            Record::TruthLandmarks(l) if lamps.is_empty() => lamps = l,
            Record::TruthCamera(c) if truth_camera.is_none() => {
                truth_camera = Some(replay::truth_camera(&c));
            }
            _ => {}
        }
    }
    // --rig RIG.toml replaces the log's rig.
    let rig_file = match &opts.rig {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
            Some(rig_model::config::Rig::from_toml_str(&text, path).map_err(|e| e.to_string())?)
        }
        None => None,
    };
    let input =
        replay::read_vehicle_log(std::path::Path::new(log), rig_file).map_err(|e| e.to_string())?;
    let rig = input.rig.clone();
    let camera = truth_camera.unwrap_or(rig.nominal);
    let first_t = input.frames.first().ok_or("no frames")?.t_us;
    let t0 = *poses.range(first_t..).next().ok_or("no truth")?.1;
    let mut track_lamp: BTreeMap<u64, u32> = BTreeMap::new();
    // The true pose in the first frame's world.
    let truth_at = |t: u64| -> Option<Pose2> {
        let p = poses.range(t..).next()?.1;
        let (c, s) = (t0.theta.cos(), t0.theta.sin());
        let (dx, dy) = (p.x - t0.x, p.y - t0.y);
        Some(Pose2::new(
            c * dx + s * dy,
            -s * dx + c * dy,
            p.theta - t0.theta,
        ))
    };
    // The lamp whose raw left pixel is nearest to `px`, seen from the true pose at `t`.
    let lamp_of = |t: u64, px: Vector2<f64>| -> Option<u32> {
        let pose = poses.range(t..).next()?.1;
        lamps
            .iter()
            .filter_map(|l| {
                let z = rig_model::project(&camera, pose, &Vector3::new(l.x, l.y, l.z));
                let z = z.ok()?;
                let rect = Vector2::new(z[0], z[1]);
                let raw = match &rig.lens {
                    None => rect,
                    Some(lens) => lens.left.unrectify(rect, camera.f, camera.cx, camera.cy)?,
                };
                Some((l.id, (raw - px).norm()))
            })
            .filter(|(_, d)| *d < LAMP_PX)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(id, _)| id)
    };
    let defaults = NavSettings::default();
    let settings = NavSettings {
        smooth_phase2: !opts.no_smoother,
        relative_lost: opts.relative_lost,
        ekf: vslam_ekf::Settings {
            max_off_axis_deg: opts.field.unwrap_or(defaults.ekf.max_off_axis_deg),
            first_estimate_pose: opts.fej_pose,
            first_estimate_prediction: !opts.no_fej_prediction,
            first_estimate_prediction_heading_sigma_rad: if opts.fej_always {
                f64::INFINITY
            } else {
                defaults.ekf.first_estimate_prediction_heading_sigma_rad
            },
            odometry_error_states: opts.error_states,
            odometry_velocity_states: opts.velocity_states,
            ..defaults.ekf
        },
        candidates: vslam_ekf::CandidateSettings {
            max_in_view: opts.max_in_view.unwrap_or(defaults.candidates.max_in_view),
            ..defaults.candidates
        },
        ..defaults
    };
    let mut nav = Navigator::new(rig.clone(), settings).map_err(|e| e.to_string())?;
    let mut odometry = input.odometry.iter().peekable();
    let mut landmark_lamp: BTreeMap<u64, Option<u32>> = BTreeMap::new();
    let mut previous: Option<Pose2> = None;
    // --missed: per lamp, frames in view of both raw images, frames with a left
    // feature on it, frames an observation of it reached the update; reported at the end for
    // the lamps in view 20 frames or more that no landmark of the final map is.
    let missed_report = opts.missed;
    let mut per_lamp: BTreeMap<u32, (u32, u32, u32, f64, f64)> = BTreeMap::new();
    let (w, h) = (f64::from(rig.width), f64::from(rig.height));
    for f in &input.frames {
        if missed_report && let Some(pose) = poses.range(f.t_us..).next().map(|(_, p)| *p) {
            let raw_of = |lens: Option<&rig_model::lens::Lens>, u: f64, v: f64| match lens {
                None => Some(Vector2::new(u, v)),
                Some(lens) => lens.unrectify(Vector2::new(u, v), camera.f, camera.cx, camera.cy),
            };
            let inside = |p: &Vector2<f64>| p.x >= 0.0 && p.x < w && p.y >= 0.0 && p.y < h;
            for l in &lamps {
                let Ok(z) = rig_model::project(&camera, &pose, &Vector3::new(l.x, l.y, l.z)) else {
                    continue;
                };
                let left = raw_of(rig.lens.as_ref().map(|s| &s.left), z[0], z[1]);
                let right = raw_of(rig.lens.as_ref().map(|s| &s.right), z[2], z[3]);
                let (Some(left), Some(right)) = (left, right) else {
                    continue;
                };
                if !(inside(&left) && inside(&right)) {
                    continue;
                }
                let off_axis = ((z[0] - camera.cx).hypot(z[1] - camera.cy) / camera.f)
                    .atan()
                    .to_degrees();
                let e = per_lamp.entry(l.id).or_insert((0, 0, 0, f64::MAX, 0.0));
                e.0 += 1;
                e.3 = e.3.min(off_axis);
                e.4 = e.4.max(off_axis);
                if f.left
                    .iter()
                    .any(|px| (Vector2::new(px.u, px.v) - left).norm() < LAMP_PX)
                {
                    e.1 += 1;
                }
            }
        }
        while let Some(s) = odometry.next_if(|s| s.t_us <= f.t_us + nav::ODOMETRY_LOOKAHEAD_US) {
            nav.push_odometry(*s).map_err(|e| e.to_string())?;
        }
        let outcome = nav
            .push_frame(f.t_us, &f.left, &f.right)
            .map_err(|e| e.to_string())?;
        if outcome.switched
            && cov_at.is_some()
            && let Some(h) = nav.smoother().handover()
        {
            let frame_t: Vec<f64> = nav
                .phase1_trajectory()
                .iter()
                .map(|(t, _)| (*t - first_t) as f64 * 1e-6)
                .collect();
            for (j, l) in h.landmarks.iter().enumerate() {
                println!(
                    "  handed over L{j} at ({:+.2}, {:+.2}, {:.2}): first seen at {} s, {} observations",
                    l.position.x,
                    l.position.y,
                    l.position.z,
                    frame_t
                        .get(l.first_frame)
                        .map_or("?".to_string(), |t| format!("{t:.2}")),
                    l.observations
                );
            }
        }
        // --held-at T: every track's lamp (the lamp whose rectified projection is nearest
        // its last measurement), and at T the lamps held while lost against the truth.
        if let (Some(at), Some(pose)) =
            (opts.held_at, poses.range(f.t_us..).next().map(|(_, p)| *p))
        {
            for t in nav.front_end().tracker().tracks() {
                if t.last_t_us != f.t_us {
                    continue;
                }
                let best = lamps
                    .iter()
                    .filter_map(|l| {
                        let z = rig_model::project(&camera, &pose, &Vector3::new(l.x, l.y, l.z))
                            .ok()?;
                        Some((
                            l.id,
                            (Vector2::new(z[0], z[1]) - Vector2::new(t.last[0], t.last[1])).norm(),
                        ))
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                if let Some((id, d)) = best
                    && d < 4.0
                {
                    track_lamp.insert(t.id.0, id);
                }
            }
            let t_s = (f.t_us - first_t) as f64 * 1e-6;
            if (t_s - at).abs() < 0.025 {
                let mapped: Vec<u32> = landmark_lamp
                    .iter()
                    .filter(|(id, _)| {
                        nav.ekf()
                            .is_some_and(|e| e.contains(vslam_ekf::LandmarkId(**id)))
                    })
                    .filter_map(|(_, l)| *l)
                    .collect();
                held_report(&nav.held_lamps(), &track_lamp, &lamps, &t0, &mapped);
            }
        }
        // --lamp ID: that lamp's stereo match and track, frame by frame, while in view.
        if let Some(watch) = opts.lamp
            && let (Some(pose), Some(l)) = (
                poses.range(f.t_us..).next().map(|(_, p)| *p),
                lamps.iter().find(|l| l.id == watch),
            )
            && let Ok(z) = rig_model::project(&camera, &pose, &Vector3::new(l.x, l.y, l.z))
        {
            let raw = match &rig.lens {
                None => Some(Vector2::new(z[0], z[1])),
                Some(lens) => {
                    lens.left
                        .unrectify(Vector2::new(z[0], z[1]), camera.f, camera.cx, camera.cy)
                }
            };
            if let Some(raw) = raw
                && raw.x >= 0.0
                && raw.x < f64::from(rig.width)
                && raw.y >= 0.0
                && raw.y < f64::from(rig.height)
            {
                let feature = f
                    .left
                    .iter()
                    .position(|px| (Vector2::new(px.u, px.v) - raw).norm() < LAMP_PX);
                // The stereo match of that feature: its rectified left pixel (the front end
                // numbers the rectified features, not the raw ones).
                let matched = feature.and_then(|i| {
                    let px = f.left.get(i)?;
                    let q = match &rig.lens {
                        None => Vector2::new(px.u, px.v),
                        Some(lens) => lens.left.rectify_point(
                            Vector2::new(px.u, px.v),
                            rig.nominal.f,
                            rig.nominal.cx,
                            rig.nominal.cy,
                        )?,
                    };
                    nav.front_end()
                        .stereo_matches()
                        .iter()
                        .find(|m| {
                            (Vector2::new(m.measurement[0], m.measurement[1]) - q).norm() < 0.5
                        })
                        .map(|m| m.measurement)
                });
                let track = nav.front_end().tracker().tracks().find(|t| {
                    t.last_t_us == f.t_us
                        && (Vector2::new(t.last[0], t.last[1]) - Vector2::new(z[0], z[1])).norm()
                            < 4.0
                });
                let bound = track.and_then(|t| nav.candidates().landmark_of(t.id.0));
                let used = bound.map(|id| {
                    (
                        outcome.accepted.iter().any(|(a, _)| *a == id),
                        outcome.rejected.contains(&id),
                        outcome.removed.contains(&id),
                        nav.ekf().and_then(|e| e.observations_of(id)),
                    )
                });
                println!("    update (accepted, rejected, removed, observations): {used:?}");
                println!(
                    "lamp {watch} t {:.2}: feature {feature:?} stereo {:?} (true {:?}) track {:?} bound {:?} retired {:?}",
                    (f.t_us - first_t) as f64 * 1e-6,
                    matched.map(|m| (m[0], m[1], m[2])),
                    (z[0], z[1], z[2]),
                    track.map(|t| (t.id.0, t.confirmed, t.hits)),
                    track.and_then(|t| nav.candidates().landmark_of(t.id.0)),
                    track.map(|t| nav.candidates().is_retired(t.id.0)),
                );
            }
        }
        let Some(ekf) = nav.ekf() else {
            continue;
        };
        let t_s = (f.t_us - first_t) as f64 * 1e-6;
        if let Some(at) = nees_at
            && t_s >= at
            && t_s < at + 0.03
        {
            print_map_nees(t_s, ekf, &lamps, worst);
        }
        if let Some((a, b)) = cov_at
            && t_s >= a
            && t_s < b
        {
            print_cov(t_s, ekf);
        }
        if let Some(a) = partial_from
            && t_s >= a
        {
            let (id0, c) = *partial.get_or_insert_with(|| {
                let pose = ekf.pose();
                (
                    ekf.landmarks().map(|l| l.id.0).max().unwrap_or(0),
                    (pose.x, pose.y),
                )
            });
            let truth = if std::env::var("PROBE_TRUE").is_ok() {
                truth_at(f.t_us).map(|t| (t, lamps.as_slice()))
            } else {
                None
            };
            print_partial(t_s, ekf, id0, c, truth);
        }
        let pose = ekf.pose();
        let jump = previous.map_or(0.0, |p| {
            ((p.x - pose.x).powi(2) + (p.y - pose.y).powi(2)).sqrt()
        });
        previous = Some(pose);
        let mut wrong = Vec::new();
        for a in &outcome.associations {
            let Some(px) = f.left.get(a.left) else {
                continue;
            };
            let lamp = lamp_of(f.t_us, Vector2::new(px.u, px.v));
            if let Some(l) = lamp
                && let Some(e) = per_lamp.get_mut(&l)
            {
                e.2 += 1;
            }
            let known = *landmark_lamp.entry(a.landmark.0).or_insert(lamp);
            if known != lamp {
                wrong.push(format!(
                    "L{}(lamp {:?}) saw {:?}{}",
                    a.landmark.0,
                    known,
                    lamp,
                    if a.accepted { "" } else { " rejected" }
                ));
            }
        }
        if t_s < from || t_s > to {
            continue;
        }
        if !every_frame
            && wrong.is_empty()
            && outcome.rematched.is_empty()
            && outcome.merged.is_empty()
            && jump < JUMP_M
            && !nav.stats().frames.is_multiple_of(100)
        {
            continue;
        }
        let Some(truth) = truth_at(f.t_us) else {
            continue;
        };
        let cov = ekf.pose_covariance();
        let rematched: Vec<String> = outcome
            .rematched
            .iter()
            .map(|(_, id)| {
                format!(
                    "L{}(lamp {:?})",
                    id.0,
                    landmark_lamp.get(&id.0).copied().flatten()
                )
            })
            .collect();
        let merged: Vec<String> = outcome
            .merged
            .iter()
            .map(|(k, d)| {
                format!(
                    "L{}(lamp {:?})<-L{}(lamp {:?})",
                    k.0,
                    landmark_lamp.get(&k.0).copied().flatten(),
                    d.0,
                    landmark_lamp.get(&d.0).copied().flatten()
                )
            })
            .collect();
        if !merged.is_empty() {
            println!("        merged {merged:?}");
        }
        // Each landmark bound again: where the map has it and where its lamp is (the first
        // frame's world).
        for (_, id) in &outcome.rematched {
            let lamp = landmark_lamp.get(&id.0).copied().flatten();
            let truth = lamp
                .and_then(|n| lamps.iter().find(|l| l.id == n))
                .map(|l| {
                    let (c, s) = (t0.theta.cos(), t0.theta.sin());
                    let (dx, dy) = (l.x - t0.x, l.y - t0.y);
                    (c * dx + s * dy, -s * dx + c * dy)
                });
            if let (Some(p), Some((tx, ty))) = (ekf.landmark_position(*id), truth) {
                println!(
                    "        L{} at ({:+.2}, {:+.2}), its lamp at ({tx:+.2}, {ty:+.2})",
                    id.0, p.x, p.y
                );
            }
        }
        println!(
            "{t_s:7.2} err x {:+.2} y {:+.2} th {:+.2} deg | sigma {:.2} {:.2} {:.2} deg | acc {} rej {} add {} | jump {jump:.2} | rematched {rematched:?} wrong {wrong:?}",
            pose.x - truth.x,
            pose.y - truth.y,
            (pose.theta - truth.theta).to_degrees(),
            cov[(0, 0)].sqrt(),
            cov[(1, 1)].sqrt(),
            cov[(2, 2)].sqrt().to_degrees(),
            outcome.accepted.len(),
            outcome.rejected.len(),
            outcome.added.len(),
        );
        if std::env::var("PROBE_ACC").is_ok() {
            let list: Vec<String> = outcome
                .accepted
                .iter()
                .map(|(id, _)| {
                    let pos = ekf.landmark_position(*id).unwrap_or_default();
                    let lp = ekf.linearisation_point(*id);
                    format!(
                        "L{} ({:.1},{:.1}) obs {} lp {}",
                        id.0,
                        pos.x,
                        pos.y,
                        ekf.observations_of(*id).unwrap_or(0),
                        lp.map_or("none".to_string(), |q| format!("{:.3}", (q - pos).norm()))
                    )
                })
                .collect();
            println!("        accepted {list:?}");
        }
        let c = ekf.camera();
        if opts.vehicle {
            let sd: Vec<String> = ekf
                .estimated_parameters()
                .iter()
                .filter_map(|&p| {
                    let i = ekf.camera_state_index(p)?;
                    let v = ekf.covariance_entry(i, i)?;
                    let ci: Vec<f64> = (0..3)
                        .map(|k| {
                            ekf.covariance_entry(k, i).unwrap_or(f64::NAN)
                                / (v.sqrt() * ekf.covariance_entry(k, k).unwrap_or(f64::NAN).sqrt())
                        })
                        .collect();
                    Some(format!(
                        "{p:?} {:.3e} corr {:.2} {:.2} {:.2}",
                        v.sqrt(),
                        ci[0],
                        ci[1],
                        ci[2]
                    ))
                })
                .collect();
            println!(
                "        sd {sd:?} n {} baseline {:.5} mm",
                ekf.state_len(),
                c.baseline * 1e3
            );
            println!("        V {:?} v {:?}", c.vehicle, outcome.accepted);
        }
    }
    if missed_report && let Some(ekf) = nav.ekf() {
        // Each landmark against its lamp (the first frame's world), the worst first.
        let (c0, s0) = (t0.theta.cos(), t0.theta.sin());
        // (error, landmark, lamp, error vector, sigmas, the lamp in the first frame's world)
        type Row = (f64, u64, u32, Vector3<f64>, Vector3<f64>, Vector3<f64>);
        let mut errors: Vec<Row> = ekf
            .landmarks()
            .filter_map(|est| {
                let (id, p) = (est.id, est.position);
                let lamp = landmark_lamp.get(&id.0).copied().flatten()?;
                let l = lamps.iter().find(|l| l.id == lamp)?;
                let (dx, dy) = (l.x - t0.x, l.y - t0.y);
                let t = Vector3::new(c0 * dx + s0 * dy, -s0 * dx + c0 * dy, l.z);
                let sd = Vector3::new(
                    est.covariance[(0, 0)].sqrt(),
                    est.covariance[(1, 1)].sqrt(),
                    est.covariance[(2, 2)].sqrt(),
                );
                Some(((p - t).norm(), id.0, lamp, p - t, sd, t))
            })
            .collect();
        errors.sort_by(|a, b| b.0.total_cmp(&a.0));
        let listed = if worst > 0 { worst } else { 12 };
        for (e, id, lamp, d, sd, t) in errors.iter().take(listed) {
            println!(
                "landmark L{id} (lamp {lamp}): {:.1} mm off: d ({:+.0}, {:+.0}, {:+.0}) mm, sd ({:.0}, {:.0}, {:.0}) mm, at ({:.1}, {:.1}, {:.1}) m",
                e * 1000.0,
                d.x * 1e3,
                d.y * 1e3,
                d.z * 1e3,
                sd.x * 1e3,
                sd.y * 1e3,
                sd.z * 1e3,
                t.x,
                t.y,
                t.z
            );
        }
    }
    if missed_report {
        let mapped: Vec<u32> = nav
            .ekf()
            .map(|ekf| {
                ekf.landmark_positions()
                    .filter_map(|(id, _)| landmark_lamp.get(&id.0).copied().flatten())
                    .collect()
            })
            .unwrap_or_default();
        for (lamp, (in_view, featured, observed, min_deg, max_deg)) in &per_lamp {
            if *in_view >= 20 && !mapped.contains(lamp) {
                let l = lamps.iter().find(|l| l.id == *lamp);
                println!(
                    "missed lamp {lamp} at {:?}: in view {in_view} frames, a feature on it in {featured}, observed by the update in {observed}, {min_deg:.0} to {max_deg:.0} degrees off the axis",
                    l.map(|l| (l.x, l.y, l.z))
                );
            }
        }
    }
    let st = nav.stats();
    println!(
        "loops: {} closed, {} ambiguous, {} refused (beyond the lost pose's reach), {} given up; {} lamps held while lost",
        st.loops_closed,
        st.loops_ambiguous,
        st.loops_refused,
        st.loops_given_up,
        st.held_while_lost
    );
    Ok(())
}

/// The held lamps against their true lamps (`--held-at`): the planar rigid fit of one onto
/// the other and each lamp's residual, metres.
fn held_report(
    held: &[(u64, Vector3<f64>, u32)],
    track_lamp: &BTreeMap<u64, u32>,
    lamps: &[vehicle_log::TruthLandmark],
    t0: &Pose2,
    mapped: &[u32],
) {
    let (c0, s0) = (t0.theta.cos(), t0.theta.sin());
    // (track, lamp, frames, held position, true position)
    type Pair = (u64, u32, u32, Vector3<f64>, Vector3<f64>);
    let pairs: Vec<Pair> = held
        .iter()
        .filter_map(|&(k, p, frames)| {
            let id = *track_lamp.get(&k)?;
            let l = lamps.iter().find(|l| l.id == id)?;
            let (dx, dy) = (l.x - t0.x, l.y - t0.y);
            Some((
                k,
                id,
                frames,
                p,
                Vector3::new(c0 * dx + s0 * dy, -s0 * dx + c0 * dy, l.z),
            ))
        })
        .collect();
    let n = pairs.len() as f64;
    if pairs.len() < 2 {
        println!("held: {} lamps, {} named", held.len(), pairs.len());
        return;
    }
    let ma = pairs.iter().fold(Vector2::zeros(), |m, p| m + p.3.xy()) / n;
    let mb = pairs.iter().fold(Vector2::zeros(), |m, p| m + p.4.xy()) / n;
    let (mut c, mut s) = (0.0, 0.0);
    for p in &pairs {
        let (a, b) = (p.3.xy() - ma, p.4.xy() - mb);
        c += a.x * b.x + a.y * b.y;
        s += a.x * b.y - a.y * b.x;
    }
    let angle = s.atan2(c);
    let (sa, ca) = angle.sin_cos();
    println!(
        "held: {} lamps, {} named; fit rotation {:.2} deg",
        held.len(),
        pairs.len(),
        angle.to_degrees()
    );
    for (k, id, frames, p, t) in &pairs {
        let a = p.xy() - ma;
        let q = Vector2::new(ca * a.x - sa * a.y, sa * a.x + ca * a.y) + mb;
        println!(
            "  track {k} lamp {id}{} frames {frames}: residual ({:+.3}, {:+.3}) height {:+.3}",
            if mapped.contains(id) { " (mapped)" } else { "" },
            q.x - t.x,
            q.y - t.y,
            p.z - t.z
        );
    }
}
