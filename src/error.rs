//! Errors and their exit statuses: 2 for a bad scene or bad arguments, 1 for anything else.

use std::fmt;
use std::path::{Path, PathBuf};

/// A problem with user input, located as precisely as we can: file, key path, line.
#[derive(Debug, Clone)]
pub struct InputError {
    pub file: PathBuf,
    /// Dotted key path inside the file, e.g. `materials.white.reflectance`; empty when none applies.
    pub key: String,
    /// 1-based line number, where the input has lines.
    pub line: Option<usize>,
    pub message: String,
}

impl InputError {
    pub fn new(file: &Path, key: impl Into<String>, line: Option<usize>, message: impl Into<String>) -> Self {
        InputError { file: file.to_path_buf(), key: key.into(), line, message: message.into() }
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if !self.key.is_empty() {
            write!(f, ": `{}`", self.key)?;
        }
        write!(f, ": {}", self.message)
    }
}

#[derive(Debug)]
pub enum Error {
    /// Bad scene, bad mesh or spectrum file, bad arguments: exit status 2.
    Input(InputError),
    /// Bad command-line usage that names no file: exit status 2.
    Usage(String),
    /// Anything else (I/O while writing outputs, ...): exit status 1.
    Other(String),
}

impl Error {
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Input(_) | Error::Usage(_) => 2,
            Error::Other(_) => 1,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Input(e) => write!(f, "{e}"),
            Error::Usage(m) => write!(f, "{m}"),
            Error::Other(m) => write!(f, "{m}"),
        }
    }
}

impl std::error::Error for Error {}

impl From<InputError> for Error {
    fn from(e: InputError) -> Self {
        Error::Input(e)
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
