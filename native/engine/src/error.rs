//! The engine's one error type: every failure a caller can cause by its input, and cancellation.

use std::fmt;

/// Bad input, described so that the caller can fix it.
#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// An argument has the wrong length, count or value; the message says which.
    InvalidInput(String),
    /// The caller's progress callback asked to stop.
    Cancelled,
}

impl Error {
    pub fn invalid(message: impl Into<String>) -> Self {
        Error::InvalidInput(message.into())
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidInput(message) => f.write_str(message),
            Error::Cancelled => f.write_str("cancelled"),
        }
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;
