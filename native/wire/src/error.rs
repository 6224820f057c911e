//! What can go wrong encoding or decoding.

/// An error of this crate: the message names the problem.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum Error {
    /// The input is not what the function takes (a size, a format).
    #[error("{0}")]
    InvalidArgument(String),
    /// Encoded data that does not decode, or decodes to the wrong size.
    #[error("{0}")]
    Corrupt(String),
}
