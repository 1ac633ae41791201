//! Links the firmware crates, and `rig-model`, `selfcal`, `track`, `vslam-ekf` and `nav` with
//! `alloc` only, and the C interface's firmware build (`stereonav-capi` without `std`), into
//! a `#![no_std]` static library (see Cargo.toml). The heap is the C program's: the C
//! interface's global allocator calls its `sn_firmware_alloc` and `sn_firmware_free`.
#![no_std]

extern crate alloc;

// The C interface's symbols (sn_*) go into this library with it.
pub use stereonav;

use alloc::vec::Vec;
use fpga_link::{Decoder, Event, Header, MAX_PACKET_LEN, encode_packet};
use harris_core::{Feature, HarrisStream, Registers};
use nalgebra::Vector3;
use rig_model::handover::{FramePair, LandmarkPair};
use rig_model::odometry::{Motion, OdomSample};
use rig_model::{CameraParams, Mount, N_PARAMS, Noise, Param, Pose2, Rig, project, triangulate};
use selfcal::solve::{SolverSettings, calibrate};
use track::{FrontEnd, FrontEndSettings, Model, Pixel};
use vslam_ekf::{Ekf, Settings};

/// Width of the test image: the detector's line buffers are sized for it at compile time.
const WIDTH: usize = 32;

/// Runs the board detector on a synthetic 32x32 image with one bright 4x4 lamp and returns the
/// number of features (1), or -1 on a configuration error. No heap, no std.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_harris_features() -> i32 {
    let regs = Registers {
        width: WIDTH,
        height: WIDTH,
        ..Registers::default()
    };
    let Ok(mut stream) = HarrisStream::<WIDTH>::new(regs) else {
        return -1;
    };
    let mut count = 0;
    for y in 0..WIDTH {
        let mut row = [0u8; WIDTH];
        if (14..18).contains(&y) {
            row[14..18].fill(255);
        }
        match stream.push_row(&row) {
            Ok(features) => count += features.len(),
            Err(_) => return -1,
        }
    }
    i32::try_from(count).unwrap_or(-1)
}

/// Encodes a packet with two features and decodes it back a byte at a time, as firmware that
/// relays the board's stream would; returns the number of features decoded (2), or -1.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_stream_round_trip() -> i32 {
    let left = [Feature {
        x_q4: 160,
        y_q4: 320,
        r: 1 << 20,
    }];
    let right = [Feature {
        x_q4: 150,
        y_q4: 320,
        r: 1 << 19,
    }];
    let mut packet = [0u8; MAX_PACKET_LEN];
    let Ok(n) = encode_packet(
        &Header {
            frame: 1,
            ..Header::default()
        },
        &left,
        &right,
        &mut packet,
    ) else {
        return -1;
    };
    let mut decoder = Decoder::new();
    let mut features = 0;
    for byte in packet.iter().take(n) {
        let mut rest = core::slice::from_ref(byte);
        loop {
            let (used, event) = decoder.decode(rest);
            rest = rest.get(used..).unwrap_or_default();
            match event {
                Some(Event::Frame(frame)) => features += frame.left().len() + frame.right().len(),
                Some(Event::Corrupt(_)) => return -1,
                None => break,
            }
        }
    }
    i32::try_from(features).unwrap_or(-1)
}

/// The rig configuration of vehicle-interfaces.md section 3 (its estimate list on the heap),
/// with a tilted mount so that f is observable.
fn rig() -> Rig {
    let mut prior = [None; N_PARAMS];
    prior[Param::F.index()] = Some(30.0);
    prior[Param::Baseline.index()] = Some(0.01);
    Rig {
        width: 752,
        height: 480,
        nominal: CameraParams {
            vehicle: Default::default(),
            f: 700.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: Mount {
                x: 0.2,
                y: -0.1,
                z: 1.0,
                roll: 0.05,
                pitch: 0.2,
                yaw: -0.1,
            },
        },
        estimate: alloc::vec![Param::F, Param::Baseline],
        prior,
        noise: Noise::white(0.3, 0.02, 0.01),
        lens: None,
        board: rig_model::Board::DEFAULT,
    }
}

/// Projects four ceiling lamps seen from a turned robot with a tilted mount, triangulates them
/// back and returns how many came back within a micrometre (4), or -1 on an error.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_rig_round_trip() -> i32 {
    let rig = rig();
    let c = rig.nominal;
    let pose = Pose2::new(3.0, -1.5, 2.0);
    let lamps: Vec<Vector3<f64>> = [(0.5, 0.0), (1.5, 0.5), (1.0, -0.8), (2.0, 0.2)]
        .into_iter()
        .map(|(ahead, left)| pose.point_in_world(&Vector3::new(ahead, left, 4.0)))
        .collect();
    let mut recovered = 0;
    for lamp in &lamps {
        let Ok(z) = project(&c, &pose, lamp) else {
            return -1;
        };
        let Ok(tri) = triangulate(&c, &z) else {
            return -1;
        };
        if (tri.p_in_world(&c, &pose) - lamp).norm() < 1e-6 {
            recovered += 1;
        }
    }
    recovered
}

/// Phase 1 as firmware would run it: the rig's nominal f is 20 px off; twelve frame pairs of a
/// robot turning and creeping under four lamps, seen by the true camera (no noise), give f back.
/// Returns 1 when the estimate is within its own sigma of the truth (the prior, 20 px away at
/// 30 px, still pulls it by about 0.6 px; the data's sigma is about 5 px), 0 when not.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_selfcal() -> i32 {
    let rig = rig();
    let mut truth = rig.nominal;
    truth.f = 720.0;
    let lamps =
        [(0.5, 0.0), (1.5, 0.5), (1.0, -0.8), (2.0, 0.2)].map(|(x, y)| Vector3::new(x, y, 4.0));
    let mut pairs = Vec::new();
    for k in 0..12u32 {
        let theta = 0.2 * f64::from(k);
        let first = Pose2::new(0.05 * f64::from(k), 0.0, theta);
        let second = Pose2::new(first.x + 0.1, 0.02, theta + 0.15);
        // The motion in the first pose's robot frame, as odometry integrates it.
        let (s, c) = (libm::sin(theta), libm::cos(theta));
        let (gx, gy) = (second.x - first.x, second.y - first.y);
        let motion = Motion {
            dx: c * gx + s * gy,
            dy: -s * gx + c * gy,
            dtheta: second.theta - first.theta,
            dt_s: 1.0,
            samples: 100,
        };
        let mut landmarks = Vec::new();
        for lamp in &lamps {
            if let (Ok(a), Ok(b)) = (
                project(&truth, &first, lamp),
                project(&truth, &second, lamp),
            ) {
                landmarks.push(LandmarkPair {
                    first: a,
                    second: b,
                });
            }
        }
        pairs.push(FramePair {
            t_us: u64::from(k) * 1_000_000,
            motion,
            landmarks,
        });
    }
    let cal = calibrate(&pairs, &rig, &rig.nominal, &SolverSettings::default());
    i32::from(libm::fabs(cal.camera.f - truth.f) <= cal.sigma(Param::F))
}

/// The navigator's association as firmware would run it: four lamps seen over five frames of a
/// creeping robot, matched left to right and tracked with the odometry. Returns the number of
/// confirmed tracks in the last frame (4), or -1 on an error.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_tracking() -> i32 {
    let rig = rig();
    let Ok(mut front) = FrontEnd::new(Model::from_rig(&rig), FrontEndSettings::default()) else {
        return -1;
    };
    let lamps =
        [(0.5, 0.0), (1.5, 0.5), (1.0, -0.8), (2.0, 0.2)].map(|(x, y)| Vector3::new(x, y, 4.0));
    let mut confirmed = 0;
    for k in 0..5u32 {
        let t_us = u64::from(k) * 50_000;
        // 0.2 m/s forward, sampled at the frame times.
        front.push_odometry(OdomSample {
            t_us,
            vx: 0.2,
            vy: 0.0,
            vtheta: 0.0,
        });
        let pose = Pose2::new(0.01 * f64::from(k), 0.0, 0.0);
        let (mut left, mut right) = (Vec::new(), Vec::new());
        for lamp in &lamps {
            let Ok(z) = project(&rig.nominal, &pose, lamp) else {
                return -1;
            };
            left.push(Pixel { u: z[0], v: z[1] });
            right.push(Pixel { u: z[2], v: z[3] });
        }
        let frame = front.push_frame(t_us, &left, &right);
        confirmed = frame.observations.iter().filter(|o| o.confirmed).count();
    }
    i32::try_from(confirmed).unwrap_or(-1)
}

/// Phase 2 as the vehicle controller would run it: the EKF maps four lamps from the first
/// frame, then predicts with the odometry and updates with the lamps seen from the new pose,
/// ten times. Returns 1 when every landmark stays within a millimetre of its lamp and the
/// baseline's variance shrank, 0 when not, -1 on an error.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_ekf() -> i32 {
    let rig = rig();
    let Ok(mut ekf) = Ekf::from_prior(&rig, Settings::default()) else {
        return -1;
    };
    let lamps =
        [(0.5, 0.0), (1.5, 0.5), (1.0, -0.8), (2.0, 0.2)].map(|(x, y)| Vector3::new(x, y, 4.0));
    let mut ids = Vec::new();
    for lamp in &lamps {
        let Ok(z) = project(&rig.nominal, &Pose2::default(), lamp) else {
            return -1;
        };
        match ekf.add_landmark(&z) {
            Ok(id) => ids.push(id),
            Err(_) => return -1,
        }
    }
    let variance =
        |ekf: &Ekf| ekf.camera_covariance()[(Param::Baseline.index(), Param::Baseline.index())];
    let before = variance(&ekf);
    for k in 1..=10u32 {
        if ekf.predict(0.2, 0.0, 0.0, 0.05).is_err() {
            return -1;
        }
        let pose = Pose2::new(0.01 * f64::from(k), 0.0, 0.0);
        let mut batch = Vec::new();
        for (id, lamp) in ids.iter().zip(&lamps) {
            let Ok(z) = project(&rig.nominal, &pose, lamp) else {
                return -1;
            };
            batch.push((*id, z));
        }
        if ekf.update(&batch).is_err() {
            return -1;
        }
    }
    let close = ekf
        .landmarks()
        .zip(&lamps)
        .all(|(l, lamp)| (l.position - lamp).norm() < 1e-3);
    i32::from(close && variance(&ekf) < before)
}

/// The navigator as the vehicle controller would run it, phase 1 skipped: odometry at 100 Hz
/// and stereo frames at 20 Hz of four lamps over a creeping robot, pushed in time order for
/// two seconds. Returns the number of landmarks mapped (4), or -1 on an error.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_navigator() -> i32 {
    let rig = rig();
    let settings = nav::NavSettings {
        skip_phase1: true,
        ..nav::NavSettings::default()
    };
    let Ok(mut navigator) = nav::Navigator::new(rig.clone(), settings) else {
        return -1;
    };
    let lamps =
        [(0.5, 0.0), (1.5, 0.5), (1.0, -0.8), (2.0, 0.2)].map(|(x, y)| Vector3::new(x, y, 4.0));
    for k in 0..=200u64 {
        let t_us = k * 10_000;
        if navigator
            .push_odometry(OdomSample {
                t_us,
                vx: 0.1,
                vy: 0.0,
                vtheta: 0.0,
            })
            .is_err()
        {
            return -1;
        }
        if k % 5 != 0 {
            continue;
        }
        let pose = Pose2::new(0.1 * t_us as f64 * 1e-6, 0.0, 0.0);
        let (mut left, mut right) = (Vec::new(), Vec::new());
        for lamp in &lamps {
            let Ok(z) = project(&rig.nominal, &pose, lamp) else {
                return -1;
            };
            left.push(Pixel { u: z[0], v: z[1] });
            right.push(Pixel { u: z[2], v: z[3] });
        }
        if navigator.push_frame(t_us, &left, &right).is_err() {
            return -1;
        }
    }
    navigator
        .ekf()
        .map_or(-1, |e| i32::try_from(e.landmark_count()).unwrap_or(-1))
}

/// The rig of these probes as the text of a rig file's JSON form (vehicle-interfaces.md
/// section 4) into `buf` (at most `cap` bytes); returns its length, or -1 when it does not
/// fit. What a C program hands `sn_navigator_new`.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_rig_json(buf: *mut u8, cap: usize) -> i32 {
    let text = rig().to_json();
    if buf.is_null() || text.len() > cap {
        return -1;
    }
    // SAFETY: `buf` has `cap >= text.len()` writable bytes (the caller's contract).
    unsafe { core::ptr::copy_nonoverlapping(text.as_ptr(), buf, text.len()) };
    i32::try_from(text.len()).unwrap_or(-1)
}

/// Step `k` (10 ms each) of the navigator probe's drive, as a vehicle would deliver it: the
/// odometry sample into `t_us`, `vx`, `vy`, `vtheta`, and on every fifth step the board's
/// packet of the stereo frame into `packet` (at most `cap` bytes; its length into
/// `packet_len`, 0 on the other steps). Returns 0, or -1 on an error.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_drive_step(
    k: u32,
    t_us: *mut u64,
    velocity: *mut f64,
    packet: *mut u8,
    cap: usize,
    packet_len: *mut usize,
) -> i32 {
    if t_us.is_null() || velocity.is_null() || packet.is_null() || packet_len.is_null() {
        return -1;
    }
    let rig = rig();
    let t = u64::from(k) * 10_000;
    // SAFETY: non-NULL outputs (the caller's contract: `velocity` has three doubles).
    unsafe {
        *t_us = t;
        *velocity = 0.1;
        *velocity.add(1) = 0.0;
        *velocity.add(2) = 0.0;
        *packet_len = 0;
    }
    if k % 5 != 0 {
        return 0;
    }
    let lamps =
        [(0.5, 0.0), (1.5, 0.5), (1.0, -0.8), (2.0, 0.2)].map(|(x, y)| Vector3::new(x, y, 4.0));
    let pose = Pose2::new(0.1 * t as f64 * 1e-6, 0.0, 0.0);
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for lamp in &lamps {
        let Ok(z) = project(&rig.nominal, &pose, lamp) else {
            return -1;
        };
        let q4 = |v: f64| libm::round(v * 16.0) as u16;
        left.push(fpga_link::Feature {
            x_q4: q4(z[0]),
            y_q4: q4(z[1]),
            r: 1 << 20,
        });
        right.push(fpga_link::Feature {
            x_q4: q4(z[2]),
            y_q4: q4(z[3]),
            r: 1 << 20,
        });
    }
    let mut buf = [0u8; MAX_PACKET_LEN];
    let header = Header {
        frame: k / 5,
        t_us: t,
        n_left: 4,
        n_right: 4,
        ..Header::default()
    };
    let Ok(n) = encode_packet(&header, &left, &right, &mut buf) else {
        return -1;
    };
    if n > cap {
        return -1;
    }
    // SAFETY: `packet` has `cap >= n` writable bytes.
    unsafe {
        core::ptr::copy_nonoverlapping(buf.as_ptr(), packet, n);
        *packet_len = n;
    }
    0
}
