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

/// Largest input file read (scene, mesh, spectrum table, IES file): a larger one is refused
/// before it is read, so no input can exhaust memory.
pub const MAX_INPUT_BYTES: u64 = 1 << 30;

/// FNV-1a, 64 bit, continuing from `h`: a digest to tell inputs apart (not a cryptographic one).
pub fn fnv1a(h: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(h, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// FNV-1a's starting value.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

thread_local! {
    /// While a scene loads (`digest_inputs`), the digest of every input file read so far.
    static INPUT_DIGEST: std::cell::Cell<Option<u64>> = const { std::cell::Cell::new(None) };
}

/// Runs `load` (a scene's load, on this thread) and returns with its result a digest of `text`
/// and of every input file it read (`read_input`): what a partial run's state is checked against,
/// so that parts of different scenes, meshes or spectra are never merged.
pub fn digest_inputs<T>(text: &str, load: impl FnOnce() -> T) -> (T, u64) {
    let outer = INPUT_DIGEST.with(|d| d.replace(Some(fnv1a(FNV_OFFSET, text.as_bytes()))));
    let result = load();
    let digest = INPUT_DIGEST.with(|d| d.replace(outer)).unwrap_or(FNV_OFFSET);
    (result, digest)
}

/// The bytes of an input file, at most `MAX_INPUT_BYTES`. `what` names it in messages.
pub fn read_input(path: &Path, what: &str) -> Result<Vec<u8>, InputError> {
    let bytes = read_input_bytes(path, what)?;
    INPUT_DIGEST.with(|d| {
        if let Some(h) = d.get() {
            d.set(Some(fnv1a(fnv1a(h, &(bytes.len() as u64).to_le_bytes()), &bytes)));
        }
    });
    Ok(bytes)
}

fn read_input_bytes(path: &Path, what: &str) -> Result<Vec<u8>, InputError> {
    use std::io::Read;
    let fail = |e: std::io::Error| InputError::new(path, "", None, format!("cannot read {what}: {e}"));
    let file = std::fs::File::open(path).map_err(fail)?;
    let meta = file.metadata().map_err(fail)?;
    if !meta.is_file() {
        return Err(InputError::new(path, "", None, format!("cannot read {what}: it is not a regular file")));
    }
    if meta.len() > MAX_INPUT_BYTES {
        return Err(InputError::new(
            path,
            "",
            None,
            format!("cannot read {what}: it is larger than {MAX_INPUT_BYTES} bytes"),
        ));
    }
    let mut bytes = Vec::new();
    file.take(MAX_INPUT_BYTES + 1).read_to_end(&mut bytes).map_err(fail)?;
    if bytes.len() as u64 > MAX_INPUT_BYTES {
        return Err(InputError::new(
            path,
            "",
            None,
            format!("cannot read {what}: it is larger than {MAX_INPUT_BYTES} bytes"),
        ));
    }
    Ok(bytes)
}

/// An input file as text in which bytes that are not UTF-8 (a Latin-1 "°" in a comment, common
/// in IES and OBJ files) become U+FFFD: they matter only where a parser reads them, and then its
/// message names their line.
pub fn read_text_lossy(path: &Path, what: &str) -> Result<String, InputError> {
    Ok(String::from_utf8_lossy(&read_input(path, what)?).into_owned())
}

/// An input file that must be UTF-8 (TOML): a bad byte is an error naming its line.
pub fn read_utf8(path: &Path, what: &str) -> Result<String, InputError> {
    String::from_utf8(read_input(path, what)?).map_err(|e| {
        let bytes = e.as_bytes();
        let at = e.utf8_error().valid_up_to();
        let line = 1 + bytes[..at].iter().filter(|&&b| b == b'\n').count();
        InputError::new(path, "", Some(line), format!("{what} is not UTF-8 text (byte {at} is not)"))
    })
}
