//! Scenario files: the committed ones load and are honest; bad ones give one-line errors
//! naming the file, the key and the problem.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::Path;

fn error_of(text: &str) -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios");
    match sim::Scenario::from_toml_str(text, "bad.toml", &dir) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

fn paper_square() -> String {
    std::fs::read_to_string(common::scenario_path("paper-square")).unwrap()
}

#[test]
fn committed_scenarios_are_honest_to_the_paper() {
    for name in [
        "paper-calibration",
        "paper-square",
        "paper-experiment",
        "warehouse",
    ] {
        let s = common::load(name);
        let c = s.true_camera();
        assert_eq!(
            (s.spec.camera.width, s.spec.camera.height),
            (752, 480),
            "{name}"
        );
        assert!((680.0..=730.0).contains(&c.f), "{name}: f {}", c.f);
        assert!(
            (0.11..=0.13).contains(&c.baseline),
            "{name}: baseline {}",
            c.baseline
        );
        assert_eq!(s.spec.noise.pixel_px, 0.3, "{name}");
        let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
        for l in &run.landmarks {
            let above = l.position.z - c.mount.z;
            assert!(
                (2.0..=3.0).contains(&above),
                "{name}: lamp {} is {above} m above",
                l.id
            );
        }
        // The nominal rig estimates what the scenario is about, with priors that cover the
        // true error.
        for p in &s.rig.estimate {
            let error = (s.rig.nominal.get(*p) - c.get(*p)).abs();
            let sigma = s.rig.prior[p.index()].unwrap();
            assert!(
                error <= 2.0 * sigma,
                "{name}: {p} off by {error}, prior {sigma}"
            );
        }
        for p in rig_model::Param::ALL {
            if !s.rig.estimate.contains(&p) {
                assert!(
                    (s.rig.nominal.get(p) - c.get(p)).abs() < 1e-12,
                    "{name}: {p} is not estimated but wrong"
                );
            }
        }
    }
    let names = |n: &str| {
        common::load(n)
            .rig
            .estimate
            .iter()
            .map(|p| p.name())
            .collect::<Vec<_>>()
    };
    assert_eq!(names("paper-calibration"), ["f", "baseline"]);
    assert_eq!(names("paper-square"), ["f", "baseline"]);
    assert_eq!(names("paper-experiment"), ["baseline"]);
    assert!(
        common::load("paper-calibration")
            .spec
            .camera
            .mount
            .pitch_deg
            >= 15.0
    );
    assert_eq!(common::load("paper-experiment").spec.world.lamps.len(), 5);
    let w = sim::simulate(&common::load("warehouse"), sim::Mode::Fast).unwrap();
    assert!(w.landmarks.len() >= 200);
}

#[test]
fn missing_key() {
    let text = paper_square().replace("seed = 5\n", "");
    assert_eq!(error_of(&text), "bad.toml: seed: missing key (line 1)");
    let text = paper_square().replace("f_px = 717.5      # nominal 700\n", "");
    let e = error_of(&text);
    assert!(e.starts_with("bad.toml: camera.f_px: missing key"), "{e}");
}

#[test]
fn wrong_type() {
    let text = paper_square().replace("seed = 5", "seed = \"five\"");
    let e = error_of(&text);
    assert!(
        e.starts_with("bad.toml: seed: wrong type: expected u64, found string \"five\""),
        "{e}"
    );
    let text = paper_square().replace(
        "{ kind = \"straight\", length_m = 2.0 }",
        "{ kind = \"straight\", length_m = \"2\" }",
    );
    let e = error_of(&text);
    let line = text
        .lines()
        .position(|l| l.contains("length_m = \"2\""))
        .unwrap()
        + 1;
    assert_eq!(
        e,
        format!(
            "bad.toml: path.segments[1].length_m: wrong type: expected f64, found string \"2\" (line {line})"
        )
    );
}

#[test]
fn unknown_key() {
    let text = paper_square().replace("seed = 5\n", "seed = 5\nspeed = 3\n");
    let e = error_of(&text);
    assert!(
        e.starts_with("bad.toml: speed: unknown key (known: description, seed"),
        "{e}"
    );
    let text = paper_square().replace("pixel_px = 0.3", "pixel_px = 0.3\npixels = 2");
    let e = error_of(&text);
    assert!(e.starts_with("bad.toml: noise.pixels: unknown key"), "{e}");
    let text = paper_square().replace("kind = \"wait\"", "kind = \"pause\"");
    let e = error_of(&text);
    assert!(
        e.starts_with("bad.toml: path.segments[0].kind: unknown value \"pause\""),
        "{e}"
    );
    let text = paper_square().replacen(
        "{ kind = \"turn\", angle_deg = 90.0 }",
        "{ kind = \"turn\", length_m = 90.0 }",
        1,
    );
    let e = error_of(&text);
    assert_eq!(
        e,
        "bad.toml: path.segments[2].angle_deg: missing key (a \"turn\" segment needs it)"
    );
    let text = paper_square().replacen(
        "{ kind = \"turn\", angle_deg = 90.0 }",
        "{ kind = \"turn\", angle_deg = 90.0, length_m = 1.0 }",
        1,
    );
    let e = error_of(&text);
    assert_eq!(
        e,
        "bad.toml: path.segments[2].length_m: not a key of a \"turn\" segment (its keys: kind, angle_deg, yaw_rate_degps)"
    );
}

#[test]
fn impossible_values() {
    for (from, to, expected) in [
        (
            "f_px = 717.5",
            "f_px = -717.5",
            "bad.toml: camera.f_px: -717.5 must be positive",
        ),
        (
            "odometry_hz = 100.0",
            "odometry_hz = 10.0",
            "bad.toml: rates.odometry_hz: 10 Hz is below the camera rate 20 Hz",
        ),
        (
            "repeat = 2",
            "repeat = 0",
            "bad.toml: path.repeat: 0 is outside 1..=10000",
        ),
        (
            "width = 752",
            "width = 5000",
            "bad.toml: camera.width: 5000 is outside 16..=4095",
        ),
        (
            "repeat = 2",
            "repeat = 1000",
            "bad.toml: path: the path takes 46333 s; at most 43200 s",
        ),
        (
            "camera_hz = 20.0",
            "camera_hz = 0.0",
            "bad.toml: rates.camera_hz: 0 is outside 0.1..=1000",
        ),
        (
            "{ kind = \"turn\", angle_deg = 90.0 },\n  { kind = \"straight\", length_m = 2.0 },\n  { kind = \"turn\", angle_deg = 90.0 },\n  { kind = \"straight\", length_m = 2.0 },\n  { kind = \"turn\", angle_deg = 90.0 },\n  { kind = \"straight\"",
            "{ kind = \"turn\", angle_deg = 90.0 },\n  { kind = \"straight\", length_m = 2.0 },\n  { kind = \"turn\", angle_deg = 90.0 },\n  { kind = \"straight\", length_m = 2.0 },\n  { kind = \"turn\", angle_deg = 90.0 },\n  { kind = \"straight\", speed_mps = 9.0",
            "bad.toml: path.segments[7].speed_mps: 9 is outside 0.001..=0.3",
        ),
    ] {
        let text = paper_square().replacen(from, to, 1);
        assert_ne!(text, paper_square(), "{from}");
        let e = error_of(&text);
        assert!(e.starts_with(expected), "{e}\nexpected {expected}");
        assert!(!e.contains('\n'));
    }
}

#[test]
fn syntax_errors_and_rig_problems_name_the_file() {
    let e = error_of("seed = 5\n[camera\n");
    assert!(e.starts_with("bad.toml: line 2: not valid TOML"), "{e}");
    let text = paper_square().replace(
        "rig = \"paper-square.rig.toml\"",
        "rig = \"nowhere.rig.toml\"",
    );
    let e = error_of(&text);
    assert!(
        e.starts_with("bad.toml: rig: cannot read rig file") && e.contains("nowhere.rig.toml"),
        "{e}"
    );
    let e = sim::Scenario::load(Path::new("/nonexistent/x.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("/nonexistent/x.toml: cannot read"), "{e}");
}

fn hall_localize() -> String {
    std::fs::read_to_string(common::scenario_path("hall-localize")).unwrap()
}

#[test]
fn start_moved_dark_added_and_world_seed_are_checked() {
    let moved = "{ kind = \"moved\", duration_s = 8.0, x_m = 27.0, y_m = 16.0, yaw_deg = -150.0, odometry = \"none\" }";
    let start = "start = { x_m = 12.0, y_m = 6.0, yaw_deg = 120.0 }";
    let dark = "dark = [13, 24, 25, 37, 43, 46, 56]";
    let segment = hall_localize()
        .lines()
        .filter(|l| l.trim_start().starts_with("{ kind"))
        .position(|l| l.contains("\"moved\""))
        .unwrap();
    let seg = |key: &str| format!("bad.toml: path.segments[{segment}].{key}");
    for (from, to, expected) in [
        (dark, "dark = [13, 70]", "bad.toml: world.dark[1]: no lamp 70: the hall's lamps are 0..=69 (lamp 70 is world.added[0]: leave it out instead)".to_string()),
        (dark, "dark = [13, 99]", "bad.toml: world.dark[1]: no lamp 99: the hall's lamps are 0..=69".to_string()),
        (dark, "dark = [13, 24, 13]", "bad.toml: world.dark[2]: lamp 13 is already dark (world.dark[0])".to_string()),
        (dark, "dark = [-1]", "bad.toml: world.dark[0]: impossible value: expected u32, found integer -1 (line ".to_string()),
        ("seed = 7070", "seed = \"hall\"", "bad.toml: world.seed: wrong type: expected u64".to_string()),
        ("{ x_m = 12.0, y_m = 8.0, z_m = 7.0 }", "{ x_m = 12.0, y_m = 8.0, z_m = inf }", "bad.toml: world.added[0].z_m: inf is not a finite number".to_string()),
        ("{ x_m = 12.0, y_m = 8.0, z_m = 7.0 }", "{ x_m = 12.0, y_m = 8.0 }", "bad.toml: world.added[0].z_m: missing key".to_string()),
        (start, "start = { x_m = nan, y_m = 6.0, yaw_deg = 120.0 }", "bad.toml: path.start.x_m: NaN is outside -100000..=100000".to_string()),
        (start, "start = { x_m = 12.0, y_m = 6.0, yaw_deg = 1e9 }", "bad.toml: path.start.yaw_deg: 1000000000 is outside -360..=360".to_string()),
        (start, "start = { x_m = 12.0, y_m = 6.0 }", "bad.toml: path.start.yaw_deg: missing key".to_string()),
        (start, "start = { x_m = 12.0, y_m = 6.0, yaw_deg = 120.0, z_m = 1.0 }", "bad.toml: path.start.z_m: unknown key (known: x_m, y_m, yaw_deg)".to_string()),
        (moved, "{ kind = \"moved\", duration_s = 0.0, x_m = 27.0, y_m = 16.0, yaw_deg = -150.0 }", format!("{}: 0 must be positive", seg("duration_s"))),
        (moved, "{ kind = \"moved\", duration_s = -8.0, x_m = 27.0, y_m = 16.0, yaw_deg = -150.0 }", format!("{}: -8 must be positive", seg("duration_s"))),
        (moved, "{ kind = \"moved\", duration_s = 8.0, y_m = 16.0, yaw_deg = -150.0 }", format!("{}: missing key (a \"moved\" segment needs it)", seg("x_m"))),
        (moved, "{ kind = \"moved\", duration_s = 8.0, x_m = inf, y_m = 16.0, yaw_deg = -150.0 }", format!("{}: inf is outside -100000..=100000", seg("x_m"))),
        (moved, "{ kind = \"moved\", duration_s = 8.0, x_m = 27.0, y_m = 16.0, yaw_deg = nan }", format!("{}: NaN is outside -360..=360", seg("yaw_deg"))),
        (moved, "{ kind = \"moved\", duration_s = 8.0, x_m = 27.0, y_m = 16.0, yaw_deg = -150.0, length_m = 1.0 }", format!("{}: not a key of a \"moved\" segment (its keys: kind, duration_s, x_m, y_m, yaw_deg, odometry)", seg("length_m"))),
        (moved, "{ kind = \"moved\", duration_s = 8.0, x_m = 27.0, y_m = 16.0, yaw_deg = -150.0, odometry = \"some\" }", format!("{}: unknown value \"some\", expected \"none\" or \"zero\"", seg("odometry"))),
        ("{ kind = \"wait\", duration_s = 2.0 }", "{ kind = \"wait\", duration_s = 2.0, odometry = \"zero\" }", "bad.toml: path.segments[0].odometry: not a key of a \"wait\" segment (its keys: kind, duration_s)".to_string()),
        ("{ kind = \"wait\", duration_s = 2.0 }", "{ kind = \"wait\", duration_s = 2.0, x_m = 1.0 }", "bad.toml: path.segments[0].x_m: not a key of a \"wait\" segment (its keys: kind, duration_s)".to_string()),
    ] {
        let text = hall_localize().replacen(from, to, 1);
        assert_ne!(text, hall_localize(), "{from}");
        let e = error_of(&text);
        assert!(e.starts_with(&expected), "{e}\nexpected {expected}");
        assert!(!e.contains('\n'));
    }
    // A panel goes dark whole.
    let real_lamps = std::fs::read_to_string(common::scenario_path("real-lamps")).unwrap();
    let partial = real_lamps.replace("[world]\n", "[world]\ndark = [0, 2, 3, 5]\n");
    assert_eq!(
        error_of(&partial),
        "bad.toml: world.dark[1]: lamp 2 is a point of world.panels[0] (lamps 2..=5), which goes dark whole: lamp 4 is not listed"
    );
    let tube = real_lamps.replace("[world]\n", "[world]\ndark = [16]\n");
    assert_eq!(
        error_of(&tube),
        "bad.toml: world.dark[0]: lamp 16 is a point of world.panels[4] (lamps 16..=17), which goes dark whole: lamp 17 is not listed"
    );
    let whole = real_lamps.replace("[world]\n", "[world]\ndark = [5, 4, 3, 2, 16, 17]\n");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios");
    let s = sim::Scenario::from_toml_str(&whole, "ok.toml", &dir).unwrap();
    assert_eq!(s.spec.world.dark.len(), 6);
    // Added lamps alone are a world; without them and the others there is none.
    let paper = std::fs::read_to_string(common::scenario_path("paper-experiment")).unwrap();
    let only_added = paper.replace("lamps = [", "added = [");
    assert_ne!(only_added, paper);
    let s = sim::Scenario::from_toml_str(&only_added, "ok.toml", &dir).unwrap();
    assert_eq!(s.spec.world.added.len(), 5);
    let start = paper.find("lamps = [").unwrap();
    let end = start + paper[start..].find("]\n").unwrap() + 2;
    let none = format!("{}added = []\n{}", &paper[..start], &paper[end..]);
    assert_eq!(
        error_of(&none),
        "bad.toml: world: no lamps: give world.lamps, world.grids, world.panels or world.added"
    );
}
