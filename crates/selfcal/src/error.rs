//! Why phase 1 refused its settings; the message is one line naming the field and the value.

/// A refused setting of phase 1 ([`SolverSettings`](crate::SolverSettings),
/// [`StableRule`](crate::StableRule), [`SmootherSettings`](crate::SmootherSettings)).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A field out of its range.
    #[error("phase-1 setting {name} = {value} must be {expected}")]
    Setting {
        /// The settings type (`"SolverSettings"`, `"StableRule"`, `"SmootherSettings"`).
        settings: &'static str,
        /// The field.
        name: &'static str,
        /// Its value (a count as `f64`).
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
}

/// What a positive real setting must be.
pub(crate) const POSITIVE: &str = "a positive finite number";

/// The first failed check of `checks` (`(field, value, ok, expected)`) as an [`Error::Setting`]
/// of `settings`.
pub(crate) fn check_fields<const N: usize>(
    settings: &'static str,
    checks: [(&'static str, f64, bool, &'static str); N],
) -> Result<(), Error> {
    for (name, value, ok, expected) in checks {
        if !ok {
            return Err(Error::Setting {
                settings,
                name,
                value,
                expected,
            });
        }
    }
    Ok(())
}
