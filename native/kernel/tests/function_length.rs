//! No function of the kernel's non-test code is longer than [`MAX_LINES`] lines, but for the
//! few hot ones in [`LONG`], each kept whole for speed (the comment at the function says why)
//! and held to the length it has.
//!
//! The crate's modules are followed from `src/lib.rs` through their `mod` declarations, as the
//! compiler does; modules, items and functions under `#[cfg(test)]` or `#[test]` are left out.
//! A function's length runs from the line of `fn` to the line of its closing brace (its doc
//! comment and attributes are not counted); a function nested in another counts as part of it.

use std::path::{Path, PathBuf};
use syn::spanned::Spanned;

/// The longest a function may be, in lines.
const MAX_LINES: usize = 80;

/// Functions left longer, and the most lines each may have: (file under `src/`, function,
/// lines). Each is hot code whose comment says why it is kept whole.
const LONG: &[(&str, &str, usize)] = &[
    ("bvh.rs", "ordered_walk", 90),
    ("integrator.rs", "shade", 86),
    ("packet.rs", "leaf_lanes", 117),
    ("packet.rs", "traverse", 160),
];

/// A function found: its file under `src/`, its name, its length in lines.
struct Function {
    file: String,
    name: String,
    lines: usize,
}

/// Whether `attrs` put the item under test: `#[cfg(test)]` or `#[test]`.
fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("test")
            || (a.path().is_ident("cfg") && a.parse_args::<syn::Ident>().is_ok_and(|i| i == "test"))
    })
}

/// Lines from the signature's first line to the block's last.
fn length(sig: &syn::Signature, block: &syn::Block) -> usize {
    block.span().end().line + 1 - sig.span().start().line
}

/// Collects the functions of a module whose items are `items`, read from `file`; `dir` is
/// where the files of its child modules are.
fn collect(items: &[syn::Item], file: &str, dir: &Path, out: &mut Vec<Function>) {
    let mut add = |name: String, lines: usize| {
        out.push(Function {
            file: file.to_string(),
            name,
            lines,
        })
    };
    let mut children = Vec::new();
    for item in items {
        match item {
            syn::Item::Fn(f) if !is_test(&f.attrs) => {
                add(f.sig.ident.to_string(), length(&f.sig, &f.block));
            }
            syn::Item::Impl(i) if !is_test(&i.attrs) => {
                for it in &i.items {
                    if let syn::ImplItem::Fn(f) = it {
                        if !is_test(&f.attrs) {
                            add(f.sig.ident.to_string(), length(&f.sig, &f.block));
                        }
                    }
                }
            }
            syn::Item::Trait(t) if !is_test(&t.attrs) => {
                for it in &t.items {
                    if let syn::TraitItem::Fn(f) = it {
                        if let Some(block) = &f.default {
                            add(f.sig.ident.to_string(), length(&f.sig, block));
                        }
                    }
                }
            }
            syn::Item::Mod(m) if !is_test(&m.attrs) => children.push(m),
            _ => {}
        }
    }
    for m in children {
        let name = m.ident.to_string();
        match &m.content {
            Some((_, items)) => collect(items, file, &dir.join(&name), out),
            None => {
                let flat = dir.join(format!("{name}.rs"));
                let path = if flat.exists() {
                    flat
                } else {
                    dir.join(&name).join("mod.rs")
                };
                read_module(&path, &dir.join(&name), out);
            }
        }
    }
}

/// Collects the functions of the module in file `path`, whose child modules are in `dir`.
fn read_module(path: &Path, dir: &Path, out: &mut Vec<Function>) {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let parsed =
        syn::parse_file(&text).unwrap_or_else(|e| panic!("cannot parse {}: {e}", path.display()));
    let src = src();
    let file = path
        .strip_prefix(&src)
        .unwrap_or(path)
        .display()
        .to_string();
    collect(&parsed.items, &file, dir, out);
}

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn functions() -> Vec<Function> {
    let mut out = Vec::new();
    read_module(&src().join("lib.rs"), &src(), &mut out);
    out
}

#[test]
fn no_function_is_longer_than_the_limit() {
    let all = functions();
    assert!(
        all.len() > 100 && all.iter().any(|f| f.file == "scene/builder.rs"),
        "the crate's functions were not all found: {} of them",
        all.len()
    );
    let mut wrong = Vec::new();
    for f in &all {
        let allowed = LONG
            .iter()
            .find(|l| l.0 == f.file && l.1 == f.name)
            .map_or(MAX_LINES, |l| l.2);
        if f.lines > allowed {
            wrong.push(format!(
                "{}: fn {} has {} lines, more than {allowed}",
                f.file, f.name, f.lines
            ));
        }
    }
    for (file, name, _) in LONG {
        if !all
            .iter()
            .any(|f| f.file == *file && f.name == *name && f.lines > MAX_LINES)
        {
            wrong.push(format!(
                "{file}: fn {name} is listed in LONG but is not longer than {MAX_LINES} lines \
                 (or is gone): take it off the list"
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "functions longer than {MAX_LINES} lines (split them, or for a hot one whose split \
         would cost speed, say why at the function and list it in LONG):\n{}",
        wrong.join("\n")
    );
}

/// The test's measure on a sample: it finds a function and counts its lines as written.
#[test]
fn measures_a_function_from_fn_to_its_closing_brace() {
    let text = "/// doc\n#[inline]\npub fn f(\n    a: u32,\n) -> u32 {\n    a\n}\n\
                #[cfg(test)]\nmod tests {\n    fn long() {\n\n\n\n}\n}\n";
    let parsed = syn::parse_file(text).unwrap();
    let mut out = Vec::new();
    collect(&parsed.items, "x.rs", Path::new("/nonexistent"), &mut out);
    let found: Vec<(&str, usize)> = out.iter().map(|f| (f.name.as_str(), f.lines)).collect();
    assert_eq!(found, vec![("f", 5)]);
}
