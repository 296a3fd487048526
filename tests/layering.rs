//! The layering of `pipeline/lib.rs`, checked against the code: every
//! `crate::<module>` path in a module's shipped code (comments and
//! `#[cfg(test)]` code left out) must point at the same module or at a layer
//! below. Inside the stages' layer only the two uses `lib.rs` names are
//! allowed. A new top-level module fails the test until it is given a layer.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::util::root;

/// The layers, top first, as `pipeline/lib.rs` states them.
const LAYERS: &[&[&str]] = &[
    &["cli"],
    &["run"],
    &["report"],
    &["results"],
    &["manifest"],
    &[
        "ingest",
        "frf",
        "fit",
        "identify",
        "validate",
        "sensitivity",
        "simulate",
        "drift",
    ],
    &["model"],
    &["lti"],
    &["poly", "units"],
];

/// Uses inside one layer that run one way (from, to).
const WITHIN_LAYER: &[(&str, &str)] = &[
    ("sensitivity", "identify"),
    ("sensitivity", "fit"),
    ("validate", "simulate"),
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

/// Whether `from` may use `to`.
fn allowed(from: &str, to: &str) -> bool {
    if from == to {
        return true;
    }
    match (layer_of(from), layer_of(to)) {
        (Some(a), Some(b)) if b > a => true,
        (Some(a), Some(b)) if a == b => WITHIN_LAYER.contains(&(from, to)),
        _ => false,
    }
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("pipeline/ is readable") {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module a file belongs to: `pipeline/run/figures.rs` -> `run`.
fn module_of(file: &Path, pipeline: &Path) -> String {
    let rel = file.strip_prefix(pipeline).expect("under pipeline/");
    let first = rel.components().next().expect("a file name");
    first
        .as_os_str()
        .to_string_lossy()
        .trim_end_matches(".rs")
        .to_string()
}

/// The file's shipped code: up to its first `#[cfg(test)]`, without
/// comments (doc comments name paths in links).
fn shipped_code(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        let code = match line.find("//") {
            Some(i) => &line[..i],
            None => line,
        };
        out.push_str(code);
        out.push('\n');
    }
    out
}

/// Every module named by a `crate::<module>` path.
fn crate_uses(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        let after = &rest[i + "crate::".len()..];
        let name: String = after
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        if !name.is_empty() {
            out.insert(name);
        }
        rest = after;
    }
    out
}

#[test]
fn every_module_imports_only_from_layers_below() {
    let pipeline = root().join("pipeline");
    let mut files = Vec::new();
    rust_files(&pipeline, &mut files);
    files.sort();
    let mut violations = Vec::new();
    let mut seen = BTreeSet::new();
    for file in &files {
        let module = module_of(file, &pipeline);
        if module == "lib" || module == "main" {
            continue;
        }
        // Whole files of unit tests.
        if file.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        seen.insert(module.clone());
        let text = std::fs::read_to_string(file).expect("a readable source file");
        for used in crate_uses(&shipped_code(&text)) {
            if !allowed(&module, &used) {
                violations.push(format!(
                    "{}: `{module}` uses `crate::{used}`",
                    file.strip_prefix(root()).unwrap_or(file).display()
                ));
            }
        }
    }
    let unplaced: Vec<&String> = seen.iter().filter(|m| layer_of(m).is_none()).collect();
    assert!(
        unplaced.is_empty(),
        "modules without a layer (add them to lib.rs's list and to LAYERS): {unplaced:?}"
    );
    assert!(
        violations.is_empty(),
        "imports that point up a layer:\n{}",
        violations.join("\n")
    );
}

/// The checker itself: it sees grouped and inline paths, ignores comments
/// and test code, and refuses an upward or sideways use.
#[test]
fn the_layering_check_can_fail() {
    let code = shipped_code(
        "use crate::lti::TransferFunction;\n\
         // crate::run is only named in a comment\n\
         fn f() -> crate::results::Results { todo!() }\n\
         #[cfg(test)]\n\
         mod tests { use crate::report; }\n",
    );
    let uses = crate_uses(&code);
    assert_eq!(
        uses.into_iter().collect::<Vec<_>>(),
        ["lti".to_string(), "results".to_string()]
    );
    assert!(allowed("model", "lti"));
    assert!(!allowed("model", "results"));
    assert!(!allowed("frf", "manifest"));
    assert!(!allowed("identify", "sensitivity"));
    assert!(allowed("sensitivity", "identify"));
    assert!(!allowed("frf", "fit"));
    assert!(!allowed("lti", "newmodule"));
}
