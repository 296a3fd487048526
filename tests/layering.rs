//! The layering of `pipeline/lib.rs`, checked against the code: every
//! `crate::<module>` path in a module's shipped code (comments and
//! `#[cfg(test)]` code left out) must point at the same module or at a layer
//! below. Inside the stages' layer only the two uses `lib.rs` names are
//! allowed. A new top-level module fails the test until it is given a layer.

use std::collections::BTreeSet;
use std::path::Path;

use crate::util::{root, rust_files};

/// The layers, top first, as `pipeline/lib.rs` states them.
const LAYERS: &[&[&str]] = &[
    &["cli"],
    &["run"],
    &["report"],
    &["analysis"],
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
        "tracking",
        "design",
    ],
    &["model"],
    &["lti"],
    &["fft", "poly", "units", "warning"],
];

/// Uses inside one layer that run one way (from, to).
const WITHIN_LAYER: &[(&str, &str)] = &[
    ("identify", "frf"),
    ("identify", "fit"),
    ("sensitivity", "identify"),
    ("sensitivity", "fit"),
    ("sensitivity", "frf"),
    ("sensitivity", "simulate"),
    ("validate", "simulate"),
    ("tracking", "validate"),
    ("tracking", "simulate"),
    ("design", "fit"),
    ("design", "frf"),
    ("design", "simulate"),
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

/// The sibling files (or folders) of one folder that `code`, the shipped
/// code of a file in it, names: through `super::` from a child file, or
/// through `crate::<folder's path>::`. `siblings` are the folder's module
/// names.
fn sibling_uses(code: &str, folder_path: &str, siblings: &BTreeSet<String>) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for prefix in ["super::".to_string(), format!("crate::{folder_path}::")] {
        let mut from = 0;
        while let Some(i) = code[from..].find(&prefix) {
            let at = from + i;
            from = at + prefix.len();
            let rest = &code[from..];
            // `super::super::` names the folder's parent, not a sibling.
            if prefix == "super::"
                && (code[..at].ends_with("super::") || rest.starts_with("super::"))
            {
                continue;
            }
            let names: Vec<String> = if let Some(group) = rest.strip_prefix('{') {
                // The first segment of each path in the group, at depth 1.
                let mut depth = 1;
                let mut names = Vec::new();
                let mut item = String::new();
                for c in group.chars() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 1 => break,
                        '}' => depth -= 1,
                        ',' if depth == 1 => {
                            names.push(std::mem::take(&mut item));
                            continue;
                        }
                        _ => {}
                    }
                    if depth == 1 {
                        item.push(c);
                    }
                }
                names.push(item);
                names
                    .iter()
                    .map(|n| {
                        n.trim()
                            .chars()
                            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                            .collect()
                    })
                    .collect()
            } else {
                vec![
                    rest.chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect(),
                ]
            };
            out.extend(names.into_iter().filter(|n| siblings.contains(n)));
        }
    }
    out
}

/// A circle in `edges` (each node's uses), if there is one.
fn find_circle(
    edges: &std::collections::BTreeMap<String, BTreeSet<String>>,
) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        edges: &std::collections::BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == node) {
            let mut circle = path[at..].to_vec();
            circle.push(node.to_string());
            return Some(circle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in edges.get(node).into_iter().flatten() {
            if let Some(c) = visit(next, edges, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    edges
        .keys()
        .find_map(|n| visit(n, edges, &mut Vec::new(), &mut done))
}

/// Inside every folder of `pipeline/`, the files' uses of one another form
/// no circle (acquire, figures and tables used each other through
/// the plot limits; joint and rig through `Evidence`; canvas and text through
/// `Outline`). A folder's `mod.rs`, which declares and re-exports its
/// children, and whole files of tests are left out.
#[test]
fn no_files_of_one_folder_use_each_other_in_a_circle() {
    let pipeline = root().join("pipeline");
    let mut dirs = vec![pipeline.clone()];
    let mut circles = Vec::new();
    while let Some(dir) = dirs.pop() {
        let mut files = BTreeSet::new();
        let mut siblings = BTreeSet::new();
        for entry in std::fs::read_dir(&dir).expect("a readable folder") {
            let path = entry.expect("a directory entry").path();
            let name = path
                .file_stem()
                .expect("a file name")
                .to_string_lossy()
                .into_owned();
            if path.is_dir() {
                dirs.push(path);
                siblings.insert(name);
            } else if path.extension().is_some_and(|e| e == "rs")
                && !["mod", "tests", "lib", "main"].contains(&name.as_str())
            {
                siblings.insert(name.clone());
                files.insert((name, path));
            }
        }
        let folder_path = dir
            .strip_prefix(&pipeline)
            .expect("under pipeline/")
            .to_string_lossy()
            .replace('/', "::");
        let mut edges = std::collections::BTreeMap::new();
        for (name, path) in &files {
            let text = std::fs::read_to_string(path).expect("a readable source file");
            let mut uses = sibling_uses(&shipped_code(&text), &folder_path, &siblings);
            uses.remove(name);
            edges.insert(name.clone(), uses);
        }
        if let Some(c) = find_circle(&edges) {
            circles.push(format!("{}: {}", dir.display(), c.join(" -> ")));
        }
    }
    assert!(
        circles.is_empty(),
        "files that use each other in a circle:\n{}",
        circles.join("\n")
    );
}

/// The circle check sees grouped uses, `crate::` paths into the same
/// folder, and a circle of three.
#[test]
fn the_circle_check_can_fail() {
    let siblings: BTreeSet<String> = ["acquire", "figures", "tables", "cache"]
        .into_iter()
        .map(String::from)
        .collect();
    let uses = sibling_uses(
        "use super::{acquire::LogStage, figures::{self, X}};\nuse super::super::cache;\nfn f() { crate::run::tables::write(); }\n",
        "run",
        &siblings,
    );
    assert_eq!(
        uses.into_iter().collect::<Vec<_>>(),
        ["acquire", "figures", "tables"]
    );
    let edges: std::collections::BTreeMap<String, BTreeSet<String>> = [
        ("acquire", "figures"),
        ("figures", "tables"),
        ("tables", "acquire"),
    ]
    .into_iter()
    .map(|(a, b)| (a.to_string(), BTreeSet::from([b.to_string()])))
    .collect();
    assert_eq!(
        find_circle(&edges).map(|c| c.len()),
        Some(4),
        "acquire -> figures -> tables -> acquire"
    );
    let mut open = edges.clone();
    open.get_mut("tables").unwrap().clear();
    assert_eq!(find_circle(&open), None);
}
