//! The crate's single error type, and how text from a file is shown in one.

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
    /// A file could not be written, or a folder made or opened, with the system's error
    /// number where there is one (`EEXIST`, `ENOSPC`, ...: see [`crate::safe_fs`]).
    #[error("{file}: {message}")]
    Fs {
        /// File name.
        file: String,
        /// The system's error number (`errno`), if the system said it.
        errno: Option<i32>,
        /// What went wrong, in words.
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
    /// The memory the input needs is not there: what is left of the process's address space
    /// (its `RLIMIT_AS`) is too small, or the system refused the allocation (see
    /// [`crate::memory`]); checked before the big arrays are made, so nothing aborts. Reads e.g.
    /// `balls.nff: the BVH of 20971510 boxes needs 6710883200 bytes of memory, more than the
    /// ... bytes of address space ...; load a smaller scene or give the process more memory`.
    #[error("{what} needs {needed} bytes of memory, {why}; load a smaller scene or give the process more memory (ulimit -v)")]
    Memory {
        /// What needs it, with the file when known.
        what: String,
        /// Bytes needed.
        needed: u64,
        /// Why they are not there.
        why: String,
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

/// At most this many characters of a file's text are echoed in an error ([`snippet`]).
pub(crate) const SNIPPET_CHARS: usize = 64;

/// At most this many characters of a message from another crate that quotes a file's text
/// ([`quoted_snippets`]).
const MESSAGE_CHARS: usize = 512;

/// Text from a file as an error shows it: control and other non-printing characters escaped
/// the way Rust's `escape_debug` does (`\u{1b}`, `\n`; quotes and backslashes are kept), and at
/// most [`SNIPPET_CHARS`] characters, the last three `...` when the text was cut. The one way
/// any text read from a file gets into an error message.
pub(crate) fn snippet(text: &str) -> String {
    escape_bounded(text, SNIPPET_CHARS)
}

/// [`snippet`] of bytes that may not be UTF-8. Only a prefix is looked at, so a huge token
/// costs nothing.
pub(crate) fn snippet_bytes(bytes: &[u8]) -> String {
    let head = bytes.get(..SNIPPET_CHARS * 4 + 4).unwrap_or(bytes);
    let text = String::from_utf8_lossy(head);
    if head.len() < bytes.len() {
        // a cut is always shown, even if the prefix itself fits
        let mut s = escape_bounded(&text, SNIPPET_CHARS);
        if !s.ends_with("...") {
            let keep: String = s.chars().take(SNIPPET_CHARS - 3).collect();
            s = keep + "...";
        }
        s
    } else {
        snippet(&text)
    }
}

/// A message from another crate (the TOML reader's) that may quote text of the file between
/// backticks or double quotes: every such piece goes through [`snippet`], and the whole is
/// escaped and bounded too.
pub(crate) fn quoted_snippets(message: &str) -> String {
    let mut out = String::new();
    let mut rest = message;
    while let Some(i) = rest.find(['`', '"']) {
        out.push_str(&snippet(&rest[..i]));
        out.push_str(&rest[i..i + 1]);
        rest = &rest[i + 1..];
    }
    out.push_str(&snippet(rest));
    escape_bounded(&out, MESSAGE_CHARS)
}

/// Escapes non-printing characters (see [`snippet`]) and keeps at most `max_chars` characters
/// of the result, ending in `...` when cut (an escape is never split).
pub(crate) fn escape_bounded(text: &str, max_chars: usize) -> String {
    let mut out = String::new();
    let mut count = 0;
    // byte length of `out` at the last piece boundary where `...` still fits
    let mut cut = 0;
    for c in text.chars() {
        let esc = c.escape_debug();
        let n = if matches!(c, '\\' | '\'' | '"') {
            1
        } else {
            esc.len()
        };
        if count + n > max_chars {
            out.truncate(cut);
            out.push_str("...");
            return out;
        }
        if n == 1 {
            out.push(c);
        } else {
            out.extend(esc);
        }
        count += n;
        if count + 3 <= max_chars {
            cut = out.len();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snippets_escape_and_bound() {
        assert_eq!(snippet("plain 'text' \\ \"q\""), "plain 'text' \\ \"q\"");
        assert_eq!(snippet("\x1b[31mred\n"), "\\u{1b}[31mred\\n");
        assert_eq!(snippet("a\u{202e}b"), "a\\u{202e}b");
        let long = "x".repeat(1000);
        let s = snippet(&long);
        assert_eq!(s.chars().count(), SNIPPET_CHARS);
        assert!(s.ends_with("..."));
        assert_eq!(snippet(&"y".repeat(64)), "y".repeat(64));
        // an escape is never cut in half
        let s = snippet(&"\u{1}".repeat(100));
        assert!(s.ends_with("\\u{1}..."), "{s}");
        assert!(s.chars().count() <= SNIPPET_CHARS);
        let s = snippet_bytes(&[b'z'; 10_000_000]);
        assert_eq!(s.chars().count(), SNIPPET_CHARS);
        assert!(s.ends_with("..."));
        assert_eq!(snippet_bytes(b"ab\xffc"), "ab\u{fffd}c");
        let m = quoted_snippets(&format!(
            "unknown field `{}`, expected `camera`",
            "f".repeat(500)
        ));
        assert!(m.starts_with("unknown field `ffff"), "{m}");
        assert!(m.ends_with("...`, expected `camera`"), "{m}");
        assert!(quoted_snippets(&"`a".repeat(100_000)).chars().count() <= MESSAGE_CHARS);
    }
}
