//! The C interface from C: `tests/c/api_test.c` (every function and every error) and the
//! firmware example `examples/c/firmware.c` (a main loop fed the paper experiment's log as a
//! UART and the wheel encoders would feed it), compiled as C99 with `-Wall -Wextra -Werror`
//! against the committed header and `libstereonav.a`, and run: the API test under valgrind
//! when it is installed (no invalid access, no leak); the firmware's map against
//! `stereonav replay`'s on the same log (the same landmarks, the parameters within a tenth of
//! their sigmas).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)]

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;

use support::{Paper, root};

/// A directory of its own for each test (they run in parallel in one process).
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("stereonav-capi-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `libstereonav.a` of this build: the test binary's profile directory holds it (cargo builds
/// every crate type of the library for the tests); built with cargo when it does not.
fn static_lib() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(Path::parent).unwrap().to_path_buf();
    let candidates = [
        profile_dir.join("libstereonav.a"),
        profile_dir.join("deps/libstereonav.a"),
    ];
    let newest = |dir: &Path| -> Option<PathBuf> {
        std::fs::read_dir(dir)
            .ok()?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("libstereonav") && n.ends_with(".a"))
            })
            .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
    };
    candidates
        .iter()
        .find(|p| p.exists())
        .cloned()
        .or_else(|| newest(&profile_dir.join("deps")))
        .expect("libstereonav.a next to the test binary")
}

/// Compiles `sources` into `out` as C99 with every warning an error.
fn compile(sources: &[PathBuf], out: &Path) {
    let lib = static_lib();
    let status = Command::new("cc")
        .args([
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-O1",
            "-g",
        ])
        .arg("-I")
        .arg(root().join("crates/capi/include"))
        .args(sources)
        .arg(&lib)
        .args(["-lpthread", "-ldl", "-lm", "-o"])
        .arg(out)
        .status()
        .expect("a C compiler (cc)");
    assert!(
        status.success(),
        "compiling {sources:?} against {}",
        lib.display()
    );
}

/// The files the C programs read: the paper experiment's board stream, and the inputs of the
/// firmware example (odometry and each frame's packet, in arrival order).
struct Inputs {
    stream: PathBuf,
    firmware: PathBuf,
}

fn inputs(paper: &Paper, dir: &Path) -> Inputs {
    // Each frame's packet again (the board's encoder), with its stamp.
    let mut frames: Vec<(u64, Vec<u8>)> = Vec::new();
    let mut decoder = fpga_link::Decoder::new();
    let mut rest: &[u8] = &paper.stream;
    loop {
        let (used, event) = decoder.decode(rest);
        rest = &rest[used..];
        match event {
            Some(fpga_link::Event::Frame(f)) => {
                let left: Vec<fpga_link::Feature> = f.left().collect();
                let right: Vec<fpga_link::Feature> = f.right().collect();
                let mut buf = vec![0_u8; fpga_link::MAX_PACKET_LEN];
                let n = fpga_link::encode_packet(f.header(), &left, &right, &mut buf).unwrap();
                buf.truncate(n);
                frames.push((f.t_us(), buf));
            }
            Some(fpga_link::Event::Corrupt(_)) => {}
            None => break,
        }
    }
    assert!(frames.len() > 900, "{} frames", frames.len());
    // The wheel encoders' samples and the frames in arrival order: each frame after the
    // samples up to its stamp (a live vehicle's order).
    let odometry = &paper.odometry;
    let sample = |file: &mut Vec<u8>, s: &rig_model::odometry::OdomSample| {
        file.push(0_u8);
        file.extend_from_slice(&s.t_us.to_le_bytes());
        for v in [s.vx, s.vy, s.vtheta] {
            file.extend_from_slice(&v.to_le_bytes());
        }
    };
    let mut file = Vec::new();
    let mut k = 0;
    for (t, packet) in &frames {
        while let Some(s) = odometry.get(k).filter(|s| s.t_us <= *t) {
            sample(&mut file, s);
            k += 1;
        }
        file.push(1_u8);
        file.extend_from_slice(&t.to_le_bytes());
        file.extend_from_slice(&u32::try_from(packet.len()).unwrap().to_le_bytes());
        file.extend_from_slice(packet);
    }
    for s in &odometry[k..] {
        sample(&mut file, s);
    }
    let (stream, firmware) = (dir.join("stream.bin"), dir.join("inputs.bin"));
    std::fs::write(&stream, &paper.stream).unwrap();
    std::fs::write(&firmware, &file).unwrap();
    Inputs { stream, firmware }
}

fn valgrind() -> bool {
    Command::new("valgrind")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn the_api_test_in_c_holds_every_check_without_an_invalid_access_or_a_leak() {
    let dir = scratch("api");
    let paper = support::paper();
    let inputs = inputs(&paper, &dir);
    let map_path = dir.join("paper.map");
    std::fs::write(&map_path, &paper.map).unwrap();
    let exe = dir.join("api_test");
    compile(&[root().join("crates/capi/tests/c/api_test.c")], &exe);
    let args = [&paper.rig_path, &map_path, &inputs.stream];
    let output = if valgrind() {
        Command::new("valgrind")
            .args([
                "--error-exitcode=99",
                "--leak-check=full",
                "--errors-for-leak-kinds=definite,indirect",
                "--quiet",
            ])
            .arg(&exe)
            .args(args)
            .output()
            .unwrap()
    } else {
        eprintln!("valgrind not found: the API test runs without it");
        Command::new(&exe).args(args).output().unwrap()
    };
    let text = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "api_test exited {:?}:\n{text}",
        output.status.code()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_firmware_example_maps_the_log_as_stereonav_replay_does() {
    let dir = scratch("firmware");
    let paper = support::paper();
    let inputs = inputs(&paper, &dir);
    let exe = dir.join("firmware");
    compile(&[root().join("examples/c/firmware.c")], &exe);
    let output = Command::new(&exe)
        .arg(&paper.rig_path)
        .arg(&inputs.firmware)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(
        output.status.success(),
        "firmware exited {:?}: {}",
        output.status.code(),
        String::from_utf8_lossy(&output.stderr)
    );
    let end = &paper.end;
    // The firmware's landmarks and parameters.
    let mut landmarks: Vec<(u64, [f64; 3])> = Vec::new();
    let mut params: Vec<(String, f64, f64)> = Vec::new();
    for line in stdout.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first() {
            Some(&"landmark") => landmarks.push((
                f[1].parse().unwrap(),
                [
                    f[2].parse().unwrap(),
                    f[3].parse().unwrap(),
                    f[4].parse().unwrap(),
                ],
            )),
            Some(&"parameter") => {
                params.push((
                    f[1].to_string(),
                    f[2].parse().unwrap(),
                    f[3].parse().unwrap(),
                ));
            }
            _ => {}
        }
    }
    assert_eq!(
        landmarks.len(),
        end.landmarks.len(),
        "the firmware's landmarks:\n{stdout}"
    );
    for (l, r) in landmarks.iter().zip(&end.landmarks) {
        assert_eq!(l.0, r.id);
        for k in 0..3 {
            let sigma = r.covariance[k][k].sqrt();
            assert!(
                (l.1[k] - r.position[k]).abs() <= 0.1 * sigma,
                "landmark {} axis {k}: firmware {} replay {} (sigma {sigma})",
                r.id,
                l.1[k],
                r.position[k]
            );
        }
    }
    assert_eq!(params.len(), rig_model::N_PARAMS);
    for (name, value, sigma) in &params {
        let r = end
            .final_camera
            .iter()
            .find(|e| e.param.name() == name)
            .unwrap();
        let tol = 0.1 * r.sigma.max(sigma.abs());
        assert!(
            (value - r.value).abs() <= tol || (value - r.value).abs() <= 1e-12 * r.value.abs(),
            "{name}: firmware {value} +- {sigma}, replay {} +- {}",
            r.value,
            r.sigma
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
