//! The one error type of the core. Every variant says when it happens; the
//! Python layer maps all of them to `pprender.Error` (a `ValueError`).

/// Errors raised by the pure-Rust core.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// A scalar parameter is not finite or outside its allowed range.
    /// `name` is the parameter as the user spells it.
    #[error("invalid {name} = {value}: {expected}")]
    InvalidParameter {
        name: &'static str,
        value: String,
        expected: String,
    },
    /// An input array has the wrong shape or shapes do not broadcast.
    #[error("{0}")]
    Shape(String),
    /// A direction is not usable (not finite, not unit length, below the horizon).
    #[error("invalid {name}: {reason}")]
    InvalidDirection { name: &'static str, reason: String },
    /// No usable graphics device, or the device failed (validation, out of memory).
    #[error("device: {0}")]
    Device(String),
    /// A render stopped because its progress callback asked it to ([`crate::render::Progress`]).
    #[error("render cancelled by its progress callback")]
    Cancelled,
}

impl Error {
    /// Shorthand for [`Error::InvalidParameter`].
    pub fn param(
        name: &'static str,
        value: impl std::fmt::Display,
        expected: impl Into<String>,
    ) -> Self {
        Error::InvalidParameter {
            name,
            value: value.to_string(),
            expected: expected.into(),
        }
    }
}

pub type Result<T> = std::result::Result<T, Error>;
