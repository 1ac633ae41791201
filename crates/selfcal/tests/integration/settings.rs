//! Every settings type of phase 1 checks its own fields and names the one out of range.

use selfcal::{Error, SmootherSettings, SolverSettings, StableRule};

fn field(e: Error) -> (&'static str, &'static str, f64) {
    match e {
        Error::Setting {
            settings,
            name,
            value,
            ..
        } => (settings, name, value),
        _ => unreachable!("a settings check gives Error::Setting"),
    }
}

#[test]
fn defaults_are_valid() {
    assert_eq!(SolverSettings::default().validate(), Ok(()));
    assert_eq!(StableRule::default().validate(), Ok(()));
    assert_eq!(SmootherSettings::default().validate(), Ok(()));
    // Counts the solver accepts at any value.
    let none = SolverSettings {
        max_iterations: 0,
        ..SolverSettings::default()
    };
    assert_eq!(none.validate(), Ok(()));
    let none = StableRule {
        min_pairs: 0,
        ..StableRule::default()
    };
    assert_eq!(none.validate(), Ok(()));
}

#[test]
fn solver_settings_name_the_bad_field() {
    let d = SolverSettings::default();
    for (bad, name) in [
        (
            SolverSettings {
                huber: f64::NAN,
                ..d
            },
            "huber",
        ),
        (SolverSettings { huber: -1.0, ..d }, "huber"),
        (
            SolverSettings {
                step_tolerance: 0.0,
                ..d
            },
            "step_tolerance",
        ),
        (
            SolverSettings {
                step_tolerance: f64::INFINITY,
                ..d
            },
            "step_tolerance",
        ),
        (
            SolverSettings {
                observable_ratio: 1.5,
                ..d
            },
            "observable_ratio",
        ),
        (
            SolverSettings {
                observable_ratio: 0.0,
                ..d
            },
            "observable_ratio",
        ),
    ] {
        let e = bad.validate().expect_err(name);
        assert_eq!(field(e).0, "SolverSettings");
        assert_eq!(field(e).1, name, "{e}");
    }
    let e = SolverSettings {
        observable_ratio: 1.5,
        ..d
    }
    .validate()
    .expect_err("ratio");
    assert_eq!(
        e.to_string(),
        "phase-1 setting observable_ratio = 1.5 must be a number in (0, 1]"
    );
}

#[test]
fn stable_rule_names_the_bad_field() {
    let d = StableRule::default();
    for (bad, name, value) in [
        (
            StableRule {
                sigma_fraction: -1.0,
                ..d
            },
            "sigma_fraction",
            -1.0,
        ),
        (
            StableRule {
                step_fraction: 0.0,
                ..d
            },
            "step_fraction",
            0.0,
        ),
        (
            StableRule {
                consecutive: 0,
                ..d
            },
            "consecutive",
            0.0,
        ),
    ] {
        let e = bad.validate().expect_err(name);
        assert_eq!(field(e), ("StableRule", name, value), "{e}");
    }
}

#[test]
fn smoother_settings_name_the_bad_field() {
    let d = SmootherSettings::default();
    let e = SmootherSettings { max_frames: 1, ..d }
        .validate()
        .expect_err("frames");
    assert_eq!(field(e), ("SmootherSettings", "max_frames", 1.0));
    assert_eq!(
        e.to_string(),
        "phase-1 setting max_frames = 1 must be at least 2"
    );
}
