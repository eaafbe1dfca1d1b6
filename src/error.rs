//! One error type for the whole program: a single human-readable line.
//!
//! Every failure the user can cause (bad file, bad flag, unsupported feature)
//! ends up here and is printed as one line by `main`, never as a panic.

use std::fmt;

#[derive(Debug, Clone, PartialEq)]
pub struct Error(pub String, pub Cause);

/// Whose mistake an error is: the command line's (exit status 2) or the
/// work's (a file, a render; exit status 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cause {
    Failure,
    Usage,
}

impl Error {
    pub fn new(msg: impl Into<String>) -> Self {
        Error(msg.into(), Cause::Failure)
    }

    /// An error in the command line itself: a flag's value or combination.
    pub fn usage(msg: impl Into<String>) -> Self {
        Error(msg.into(), Cause::Usage)
    }

    pub fn into_usage(self) -> Self {
        Error(self.0, Cause::Usage)
    }

    pub fn is_usage(&self) -> bool {
        self.1 == Cause::Usage
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Keep it on one line whatever the source said.
        f.write_str(&self.0.replace('\n', " "))
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;

/// `bail!("...")` returns an `Error` built with `format!`.
#[macro_export]
macro_rules! bail {
    ($($arg:tt)*) => { return Err($crate::error::Error::new(format!($($arg)*))) };
}
