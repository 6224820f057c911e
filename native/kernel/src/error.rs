//! The crate's single error type.

/// Everything that can go wrong in the kernel: parsing, I/O, limits, bad arguments, image output.
///
/// The `Display` form is meant for users: parse errors read
/// `balls.nff:12: polygon needs at least 3 vertices, got 2`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    /// A syntax or semantic error at a known line of a scene file (lines count from 1).
    #[error("{file}:{line}: {message}")]
    Parse {
        /// File name as given to the parser.
        file: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A scene file (or a file it references) is invalid, without a useful line number.
    #[error("{file}: {message}")]
    Scene {
        /// File name.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// A file could not be read or written.
    #[error("{file}: {message}")]
    Io {
        /// File name.
        file: String,
        /// The operating system's message.
        message: String,
    },
    /// A documented upper bound (see [`crate::limits`]) was exceeded; checked before allocating.
    /// Reads e.g. `ray depth is 1000, more than the limit of 64 (limits::MAX_DEPTH); raise the
    /// constant in native/kernel/src/limits.rs and rebuild`.
    #[error("{what} is {value}{unit}, more than the limit of {max} (limits::{constant}); {hint}")]
    Limit {
        /// Which quantity (e.g. `ray depth`, `resolution 100000x100000`).
        what: String,
        /// The requested value.
        value: u64,
        /// Unit after the value, with its leading space (`" pixels"`), or empty.
        unit: &'static str,
        /// The largest accepted value.
        max: u64,
        /// Name of the constant in [`crate::limits`] holding `max`.
        constant: &'static str,
        /// How to get past the bound.
        hint: &'static str,
    },
    /// A valid request the kernel does not implement (e.g. an unknown file extension).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// A caller passed an invalid argument (e.g. a pixel span outside the image).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// Encoding or writing an image failed.
    #[error("image: {0}")]
    Image(String),
}

impl Error {
    pub(crate) fn parse(file: &str, line: usize, message: impl Into<String>) -> Error {
        Error::Parse {
            file: file.to_string(),
            line,
            message: message.into(),
        }
    }

    pub(crate) fn scene(file: &str, message: impl Into<String>) -> Error {
        Error::Scene {
            file: file.to_string(),
            message: message.into(),
        }
    }
}
