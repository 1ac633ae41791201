//! `stereonav map import` end to end (vehicle-interfaces.md section 5, docs/maps.md): the
//! lighting plan of a simulated hall (the true lamps of `hall-localize.toml`) made into a map
//! without a rig, which `stereonav localize` refuses in one line without `--rig` and localises
//! on with it; the same plan with `--rig` carried in the map; and one-line errors naming the
//! line for every kind of bad plan.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Output;

use common::{assert_one_line_error, s, stereonav};
use map_file::Map;
use serde_json::Value;

fn scratch(name: &str) -> PathBuf {
    common::scratch("map-import-cli", name)
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name)
}

fn write(name: &str, text: &str) -> PathBuf {
    let path = scratch(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// `stereonav map import PLAN --out OUT [extra...]`.
fn import(plan: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["map", "import", s(plan), "--out", s(out)];
    args.extend_from_slice(extra);
    stereonav(&args)
}

/// The hall-localize drive simulated (log, nominal rig, truth), and its hall's lamps (the
/// truth's lit lamps of the 70 planned, the 3 added since left out) as a plan in the hall's
/// frame, positions rounded to the millimetre as a survey gives them.
fn hall() -> (PathBuf, PathBuf, PathBuf) {
    let (log, rig, truth) = (
        scratch("hall.mcap"),
        scratch("hall.rig.toml"),
        scratch("hall-truth.json"),
    );
    ok(&stereonav(&[
        "simulate",
        s(&scenario("hall-localize.toml")),
        "--out",
        s(&log),
        "--rig",
        s(&rig),
        "--truth",
        s(&truth),
    ]));
    let truth: Value = serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    let mut csv = String::from("# hall-localize's hall\nid,x,y,z\n");
    for l in truth["landmarks"].as_array().unwrap() {
        if l["id"].as_u64().unwrap() < 70 {
            let c = |k: &str| l[k].as_f64().unwrap();
            writeln!(csv, "{},{:.3},{:.3},{:.3}", l["id"], c("x"), c("y"), c("z")).unwrap();
        }
    }
    (log, rig, write("hall-plan.csv", &csv))
}

#[test]
fn a_plan_becomes_a_map_that_localize_runs_on_with_a_rig() {
    let (log, rig, plan) = hall();
    let map = scratch("hall-plan.map");
    let text = ok(&import(&plan, &map, &["--sigma", "0.01"]));
    assert!(text.starts_with(&format!("{}: ", s(&map))), "{text}");
    assert!(text.contains("lamps from the lighting plan"), "{text}");
    assert!(text.contains("no rig"), "{text}");
    assert_eq!(text.lines().count(), 1, "{text}");
    let saved = Map::load(&map).unwrap();
    assert!(
        std::fs::read(&map)
            .unwrap()
            .starts_with(b"stereonav-map 2 ")
    );
    assert_eq!(saved.source_plan.as_deref(), Some(s(&plan)));
    assert!(saved.rig.is_none() && saved.parameters.is_empty());
    assert!(saved.landmarks.len() >= 60, "{}", saved.landmarks.len());
    assert!(
        saved
            .landmarks
            .iter()
            .all(|l| l.covariance[2][2] == 0.01 * 0.01 && l.id < 70)
    );

    // Without a rig: one line saying what to give; nothing written.
    let (summary, traj) = (scratch("hall-plan.json"), scratch("hall-plan.csv.traj"));
    let out = stereonav(&[
        "localize",
        s(&log),
        "--map",
        s(&map),
        "--summary",
        s(&summary),
        "--trajectory",
        s(&traj),
    ]);
    assert_one_line_error(
        &out,
        &format!(
            "stereonav: error: {}: the map has no rig (it was imported from the lighting plan {} \
             without one): give the vehicle's rig file (--rig RIG.toml)",
            s(&map),
            s(&plan)
        ),
    );
    assert!(
        !summary.exists() && !traj.exists(),
        "no output before the map is checked"
    );

    // With the vehicle's rig: it localises, in the hall's frame (the truth's).
    let text = ok(&stereonav(&[
        "localize",
        s(&log),
        "--map",
        s(&map),
        "--rig",
        s(&rig),
        "--summary",
        s(&summary),
    ]));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let fixes = doc["localized_t_us"].as_array().unwrap();
    assert!(!fixes.is_empty(), "{text}");
    let truth = &doc["truth"];
    assert_eq!(truth["wrong_frames"].as_u64(), Some(0), "{text}");
    assert!(truth["ate_max_m"].as_f64().unwrap() <= 0.25, "{text}");
    let frames = truth["frames"].as_u64().unwrap();
    assert!(
        truth["localized_frames"].as_u64().unwrap() * 100 >= frames * 85,
        "{text}"
    );

    // With --rig at import the map carries it (version 1) and localize needs none.
    let with_rig = scratch("hall-plan-rig.map");
    let text = ok(&import(&plan, &with_rig, &["--rig", s(&rig)]));
    assert!(text.contains("the rig of"), "{text}");
    assert!(
        std::fs::read(&with_rig)
            .unwrap()
            .starts_with(b"stereonav-map 1 ")
    );
    let carried = Map::load(&with_rig).unwrap();
    assert!(carried.rig.is_some());
    assert!(
        carried
            .landmarks
            .iter()
            .all(|l| l.covariance[0][0] == 0.02 * 0.02)
    );
    let text = ok(&stereonav(&["localize", s(&log), "--map", s(&with_rig)]));
    assert!(text.contains(", 0 frames localised more than"), "{text}");
}

/// Every kind of bad plan: a non-zero exit, one line naming the file, the line and the
/// problem, and no map written.
#[test]
fn bad_plans_are_refused_with_one_line_naming_the_line() {
    let cases: [(&str, &str, &str); 11] = [
        (
            "no-z.csv",
            "x,y\n1,2\n",
            "no-z.csv:1: the header has no 'z' column",
        ),
        (
            "typo.csv",
            "x,y,z,sigam\n1,2,3,0.1\n",
            "typo.csv:1: unknown column 'sigam'",
        ),
        (
            "word.csv",
            "x,y,z\n1,2,3\n1,2,high\n",
            "word.csv:3: z 'high' is not a number",
        ),
        (
            "nan.csv",
            "x,y,z\n1,NaN,3\n",
            "nan.csv:2: y is NaN, not a finite number",
        ),
        (
            "inf.csv",
            "x,y,z\ninf,2,3\n",
            "inf.csv:2: x is inf, not a finite number",
        ),
        (
            "sigma.csv",
            "x,y,z,sigma\n1,2,3,0.1\n1,2,3,0\n",
            "sigma.csv:3: sigma 0 is not positive",
        ),
        (
            "dup.csv",
            "id,x,y,z\n5,1,2,3\n5,2,2,3\n",
            "dup.csv:3: id 5 is given twice (first on line 2)",
        ),
        ("empty.csv", "", "empty.csv:1: no header line"),
        (
            "header-only.csv",
            "x,y,z\n",
            "header-only.csv:1: no lamps: no row follows the header",
        ),
        (
            "fields.csv",
            "x,y,z\n1,2,3\n1,2\n",
            "fields.csv:3: 2 fields, the header names 3 columns",
        ),
        (
            "negative.csv",
            "x,y,z,sigma\n1,2,3,-0.5\n",
            "negative.csv:2: sigma -0.5 is not positive",
        ),
    ];
    for (name, text, message) in cases {
        let out_map = scratch(&format!("{name}.map"));
        let out = import(&write(name, text), &out_map, &[]);
        assert_one_line_error(&out, message);
        assert!(!out_map.exists(), "{name}: nothing written");
    }
    let plan = write("good.csv", "x,y,z\n1,2,3\n");
    let out = import(&plan, &scratch("never.map"), &["--sigma", "0"]);
    assert_one_line_error(
        &out,
        "the default lamp sigma 0 m is not a positive, finite number",
    );
    let out = import(&plan, &scratch("never.map"), &["--sigma", "two"]);
    assert_one_line_error(&out, "--sigma");
    let out = import(
        Path::new("/nonexistent/plan.csv"),
        &scratch("never.map"),
        &[],
    );
    assert_one_line_error(&out, "/nonexistent/plan.csv");
    let out = import(&plan, Path::new("/nonexistent/dir/x.map"), &[]);
    assert_one_line_error(&out, "/nonexistent/dir/x.map");
    let out = import(
        &plan,
        &scratch("never.map"),
        &["--rig", "/nonexistent/rig.toml"],
    );
    assert_one_line_error(&out, "/nonexistent/rig.toml");
    assert!(!scratch("never.map").exists());
}
