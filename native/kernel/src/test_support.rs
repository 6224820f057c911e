//! What the kernel's unit tests share: a xorshift generator for test data, a folder's names,
//! and the TOML example of a module's doc.

use std::path::Path;

/// The next value of the xorshift sequence in `seed`, in [-1, 1) (24 bits).
pub(crate) fn rng(seed: &mut u64) -> f32 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
}

/// The names in the folder `dir`, sorted.
pub(crate) fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The ```` ```toml ```` example of the module doc (`//!` lines) in `source`, as plain TOML.
pub(crate) fn doc_example(source: &str) -> String {
    let start = source.find("//! ```toml\n").unwrap() + 12;
    let end = source[start..].find("//! ```\n").unwrap() + start;
    source[start..end]
        .lines()
        .map(|l| {
            l.strip_prefix("//! ")
                .unwrap_or(l.strip_prefix("//!").unwrap_or(l))
        })
        .collect::<Vec<_>>()
        .join("\n")
}
