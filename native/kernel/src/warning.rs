//! Warnings: input that parses and renders, but maybe not as the author meant (a zero-radius
//! sphere that shows nothing, a colour above 1, an OBJ face whose material is not in its MTL).
//!
//! Input that cannot mean what it says is an [`Error`](crate::Error) instead, and stops the
//! parse before any work; the table of which is which, and why, is in `docs/scene-format.md`.
//! A parsed [`Scene`](crate::Scene) keeps its warnings ([`Scene::warnings`](crate::Scene::warnings)):
//! the first [`MAX_WARNINGS`], each with its file and line, and a
//! count of the rest, so a huge file of degenerate lines costs no more memory than a small one.

use crate::limits::MAX_WARNINGS;
use crate::scene::SceneBuilder;
use std::fmt;

/// One warning: where, and what may not be as meant.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Warning {
    /// The file it is about, as the parser was given it (the scene file, or a referenced mesh).
    pub file: String,
    /// 1-based line, or `None` when the warning is about the file as a whole.
    pub line: Option<usize>,
    /// What may not be as meant (text of the file only through [`crate::error`]'s snippets).
    pub message: String,
}

impl fmt::Display for Warning {
    /// `file:line: warning: message`, the form compilers use (`file: warning: message` without
    /// a line).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{}: warning: {}", self.file, line, self.message),
            None => write!(f, "{}: warning: {}", self.file, self.message),
        }
    }
}

/// The warnings of one parse: at most [`MAX_WARNINGS`] kept, the rest only counted.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Warnings {
    kept: Vec<Warning>,
    omitted: u64,
}

impl Warnings {
    /// Adds a warning. `message` is only called while there is room, so past the cap a warning
    /// costs a counter increment and no allocation.
    pub fn add(&mut self, file: &str, line: Option<usize>, message: impl FnOnce() -> String) {
        if self.kept.len() < MAX_WARNINGS {
            self.kept.push(Warning {
                file: file.to_string(),
                line,
                message: message(),
            });
        } else {
            self.omitted = self.omitted.saturating_add(1);
        }
    }

    /// The warnings kept, in the order found (the first [`MAX_WARNINGS`]).
    pub fn kept(&self) -> &[Warning] {
        &self.kept
    }

    /// How many more there were, beyond those kept.
    pub fn omitted(&self) -> u64 {
        self.omitted
    }

    /// All warnings found, kept or not.
    pub fn total(&self) -> u64 {
        self.kept.len() as u64 + self.omitted
    }

    /// Whether there were none.
    pub fn is_empty(&self) -> bool {
        self.total() == 0
    }

    /// Takes in the warnings of another parse (an instanced mesh's), under the same cap.
    pub fn absorb(&mut self, other: Warnings) {
        let room = MAX_WARNINGS.saturating_sub(self.kept.len());
        let total = other.total();
        let taken = other.kept.len().min(room);
        self.kept.extend(other.kept.into_iter().take(taken));
        self.omitted = self.omitted.saturating_add(total - taken as u64);
    }
}

/// Warnings about a scene as a whole (NFF and TOML): nothing to see, or no light to see by.
pub(crate) fn scene_warnings(b: &mut SceneBuilder, file: &str) {
    if b.primitive_count() == 0 {
        b.warnings.add(file, None, || {
            "the scene has no objects to render: the image is the background only".into()
        });
    }
    if b.lights.is_empty() {
        b.warnings.add(file, None, || {
            "the scene has no lights: only the ambient term lights it".into()
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_and_cap() {
        let mut w = Warnings::default();
        assert!(w.is_empty());
        w.add("a.nff", Some(3), || "sphere has radius 0".into());
        w.add("m.obj", None, || "2 faces".into());
        assert_eq!(
            w.kept()[0].to_string(),
            "a.nff:3: warning: sphere has radius 0"
        );
        assert_eq!(w.kept()[1].to_string(), "m.obj: warning: 2 faces");
        for i in 0..1000 {
            w.add("a.nff", Some(i), || format!("n {i}"));
        }
        assert_eq!(w.kept().len(), MAX_WARNINGS);
        assert_eq!(w.omitted(), 1002 - MAX_WARNINGS as u64);
        assert_eq!(w.total(), 1002);
        // past the cap the message is never made
        w.add("a.nff", None, || unreachable!("no room"));
    }
}
