//! Why a lamp gets a second landmark (issue 35): the navigator run over a log frame by frame,
//! and for every landmark added within `RADIUS` of one already in the map (a twin: lamps and
//! sprinkler heads are metres apart), the state of that older landmark at the frame before,
//! as the map matching saw it: predicted inside the rectified image (the test
//! `Ekf::visible_landmarks` makes) or only inside the raw image through the lens, the
//! Mahalanobis distance of the new landmark's first measurement from its prediction against
//! the match gate, whether it was observed under another track, how many landmarks were
//! inside the gate. Then a table of the causes.
//!
//! `cargo run --release -p replay --example duplicate_probe -- LOG.mcap [RIG.toml]`
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::collections::BTreeMap;
use std::process::ExitCode;

use nalgebra::{Matrix4, Vector2, Vector3, Vector4};
use nav::{NavSettings, Navigator};
use vslam_ekf::LandmarkId;

/// A landmark added this close to an existing one is taken for the same lamp, metres.
const RADIUS: f64 = 0.5;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("duplicate_probe: {e}");
            ExitCode::FAILURE
        }
    }
}

/// What the map matching could see of one landmark before a frame.
struct Seen {
    position: Vector3<f64>,
    z: Vector4<f64>,
    s_inv: Matrix4<f64>,
    in_rectified: bool,
    in_raw: bool,
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: duplicate_probe LOG.mcap [RIG.toml]";
    let log = args.first().ok_or(usage)?;
    let rig = match args.get(1) {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
            Some(rig_model::config::Rig::from_toml_str(&text, path).map_err(|e| e.to_string())?)
        }
        None => None,
    };
    let input =
        replay::read_vehicle_log(std::path::Path::new(log), rig).map_err(|e| e.to_string())?;
    let rig = input.rig.clone();
    let settings = NavSettings::default();
    let gate = vslam_ekf::chi2::chi2_quantile(settings.map_match_probability, 4.0);
    let mut nav = Navigator::new(rig.clone(), settings).map_err(|e| e.to_string())?;
    let (w, h) = (f64::from(rig.width), f64::from(rig.height));
    let inside = |p: Vector2<f64>| p.x >= 0.0 && p.x < w && p.y >= 0.0 && p.y < h;
    let mut odometry = input.odometry.iter().peekable();
    let mut causes: BTreeMap<&'static str, usize> = BTreeMap::new();
    let mut twins = 0usize;
    let mut added_total = 0usize;
    for f in &input.frames {
        while let Some(s) = odometry.next_if(|s| s.t_us <= f.t_us) {
            nav.push_odometry(*s).map_err(|e| e.to_string())?;
        }
        // Every landmark as the map matching of this frame sees it (before the frame's own
        // prediction: close enough for a diagnosis at 20 Hz).
        let mut before: BTreeMap<LandmarkId, Seen> = BTreeMap::new();
        if let Some(ekf) = nav.ekf() {
            let camera = ekf.camera();
            for l in ekf.landmarks() {
                let Ok((z, s)) = ekf.predict_measurement(l.id) else {
                    continue;
                };
                let Some(s_inv) = s.try_inverse() else {
                    continue;
                };
                let left = Vector2::new(z[0], z[1]);
                let right = Vector2::new(z[2], z[3]);
                let in_raw = match &rig.lens {
                    None => inside(left) && inside(right),
                    Some(lens) => {
                        let raw = |lens: &rig_model::lens::Lens, p: Vector2<f64>| {
                            lens.unrectify(p, camera.f, camera.cx, camera.cy)
                                .is_some_and(inside)
                        };
                        raw(&lens.left, left) && raw(&lens.right, right)
                    }
                };
                before.insert(
                    l.id,
                    Seen {
                        position: l.position,
                        z,
                        s_inv,
                        in_rectified: inside(left) && inside(right),
                        in_raw,
                    },
                );
            }
        }
        let outcome = nav
            .push_frame(f.t_us, &f.left, &f.right)
            .map_err(|e| e.to_string())?;
        let Some(ekf) = nav.ekf() else {
            continue;
        };
        let observed = outcome.observed();
        for &id in &outcome.added {
            added_total += 1;
            let (Some(new), Ok((z_new, _))) = (ekf.landmark(id), ekf.predict_measurement(id))
            else {
                continue;
            };
            let p = new.position;
            let Some((old_id, old)) = before.iter().map(|(i, s)| (*i, s)).min_by(|a, b| {
                (a.1.position - p)
                    .norm()
                    .total_cmp(&(b.1.position - p).norm())
            }) else {
                continue;
            };
            let apart = (old.position - p).norm();
            if apart > RADIUS {
                continue;
            }
            twins += 1;
            let d2 = {
                let nu = z_new - old.z;
                nu.dot(&(old.s_inv * nu))
            };
            let in_gate = before
                .values()
                .filter(|s| {
                    let nu = z_new - s.z;
                    nu.dot(&(s.s_inv * nu)) <= gate
                })
                .count();
            let cause = if observed.contains(&old_id) {
                "the old landmark was observed under another track"
            } else if !old.in_rectified && old.in_raw {
                "predicted outside the rectified image, inside the raw one"
            } else if !old.in_rectified {
                "predicted outside both images"
            } else if d2 > gate {
                "outside the match gate"
            } else if in_gate > 1 {
                "more than one landmark inside the gate"
            } else {
                "inside the gate, alone: declined elsewhere"
            };
            *causes.entry(cause).or_default() += 1;
            println!(
                "t {:.2} s: landmark {} added {:.3} m from landmark {}: {cause} (d2 {:.1}, gate {:.1}, {} in gate, sigma of the old {:.3} m)",
                f.t_us as f64 * 1e-6,
                id.0,
                apart,
                old_id.0,
                d2,
                gate,
                in_gate,
                ekf.landmark(old_id).map_or(f64::NAN, |l| l
                    .covariance
                    .diagonal()
                    .map(f64::sqrt)
                    .max()),
            );
        }
    }
    println!("\n{added_total} landmarks added, {twins} within {RADIUS} m of an older one:");
    for (cause, n) in &causes {
        println!("  {n:5}  {cause}");
    }
    Ok(())
}
