//! Why a set of settings cannot be used.

/// A setting out of its range; the message names the setting, its value and what it must be.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SettingsError {
    /// A real-valued setting is NaN, infinite where it may not be, or out of range.
    #[error("{name} = {value} must be {expected}")]
    Real {
        /// The setting, as `struct.field`.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// A count is out of range.
    #[error("{name} = {value} must be {expected}")]
    Count {
        /// The setting, as `struct.field`.
        name: &'static str,
        /// Its value.
        value: u64,
        /// What it must be.
        expected: &'static str,
    },
}

/// Checks that `value` is finite and at least `min` (or above it when `strict`).
pub(crate) fn check_real(
    name: &'static str,
    value: f64,
    min: f64,
    strict: bool,
    expected: &'static str,
) -> Result<(), SettingsError> {
    let ok = value.is_finite() && if strict { value > min } else { value >= min };
    if ok {
        Ok(())
    } else {
        Err(SettingsError::Real {
            name,
            value,
            expected,
        })
    }
}

/// Checks that a count is at least `min`.
pub(crate) fn check_count(
    name: &'static str,
    value: u64,
    min: u64,
    expected: &'static str,
) -> Result<(), SettingsError> {
    if value >= min {
        Ok(())
    } else {
        Err(SettingsError::Count {
            name,
            value,
            expected,
        })
    }
}
