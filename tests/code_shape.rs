//! The shape of the code, checked: every module header under `pipeline/`
//! fits on a screen (at most `MAX_HEADER_LINES` lines of `//!`). A header
//! says what the module does, its entry points and the paper's equations;
//! derivations and evidence live in docs/methods.md, measurements in
//! docs/accuracy.md. And docs/developers.md's map of the code is the tree:
//! its layers name every module of lib.rs, and its paragraphs on
//! `identify/`, `analysis/` and `run/` every file there.

use std::path::Path;

use crate::util::{root, rust_files};

/// The most `//!` lines a module header may have: a screen.
const MAX_HEADER_LINES: usize = 15;

/// How many `//!` lines the file's leading block holds, blank `//!` lines
/// included: the lines from the top that start with `//!`, blank lines
/// between them passed over, up to the first other line.
fn header_lines(text: &str) -> usize {
    let mut count = 0;
    for line in text.lines() {
        let line = line.trim_start();
        if line.starts_with("//!") {
            count += 1;
        } else if !line.is_empty() {
            break;
        }
    }
    count
}

#[test]
fn no_module_header_is_longer_than_a_screen() {
    let pipeline = root().join("pipeline");
    let mut files = Vec::new();
    rust_files(&pipeline, &mut files);
    files.sort();
    assert!(
        !files.is_empty(),
        "no .rs files under {}",
        pipeline.display()
    );
    let long: Vec<String> = files
        .iter()
        .filter_map(|file| {
            let text = std::fs::read_to_string(file).expect("a readable source file");
            let n = header_lines(&text);
            (n > MAX_HEADER_LINES).then(|| {
                format!(
                    "{}: {n} lines of //!",
                    file.strip_prefix(root()).unwrap_or(file).display()
                )
            })
        })
        .collect();
    assert!(
        long.is_empty(),
        "module headers longer than {MAX_HEADER_LINES} lines of //! (keep what the module \
         does, its entry points and equations; move derivations to docs/methods.md):\n{}",
        long.join("\n")
    );
}

/// The counter itself: blank `//!` lines count, the block ends at the first
/// line of code, and `//!` further down is not the header.
#[test]
fn the_header_check_can_fail() {
    let long: String = (0..MAX_HEADER_LINES + 1)
        .map(|i| {
            if i == 3 {
                "//!\n".to_string()
            } else {
                format!("//! line {i}\n")
            }
        })
        .collect();
    let text = format!("{long}\nuse std::fs;\n//! not the header\n");
    assert_eq!(header_lines(&text), MAX_HEADER_LINES + 1);
    assert!(header_lines(&text) > MAX_HEADER_LINES);
    assert_eq!(header_lines("//! one\n//!\n//! three\n\nfn main() {}\n"), 3);
    assert_eq!(header_lines("fn main() {}\n//! late\n"), 0);
    assert_eq!(header_lines(""), 0);
}

/// The top-level modules lib.rs declares (`pub mod x;`).
fn lib_modules(lib: &str) -> std::collections::BTreeSet<String> {
    lib.lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .map(|m| m.trim_end_matches(';').to_string())
        .collect()
}

/// The module names of the `pipeline/` part of the layout block: the lines
/// after the one naming `pipeline/`, up to the next top-level entry, that
/// start at the names' column (the least indented), each up to the gap
/// before its description; deeper lines continue a description.
fn mapped_modules(layout: &str) -> std::collections::BTreeSet<String> {
    let section: Vec<&str> = layout
        .lines()
        .skip_while(|l| !l.starts_with("pipeline/"))
        .skip(1)
        .take_while(|l| l.starts_with(' '))
        .collect();
    let indent = |l: &str| l.len() - l.trim_start().len();
    let column = section.iter().map(|l| indent(l)).min().unwrap_or(0);
    section
        .iter()
        .filter(|l| indent(l) == column)
        .flat_map(|l| {
            l.trim_start()
                .split("  ")
                .next()
                .unwrap_or("")
                .split_whitespace()
        })
        .map(str::to_string)
        .collect()
}

/// The `.rs` files a paragraph names in backticks, relative to its folder
/// (`joint/select.rs`); a file named from the root (`pipeline/...`) is
/// another folder's.
fn named_files(paragraph: &str) -> std::collections::BTreeSet<String> {
    paragraph
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|w| w.ends_with(".rs") && !w.contains(' ') && !w.starts_with("pipeline/"))
        .map(str::to_string)
        .collect()
}

/// Every `.rs` file under `dir` as a path relative to it, but the tests.
fn files_of(dir: &Path) -> std::collections::BTreeSet<String> {
    let mut files = Vec::new();
    rust_files(dir, &mut files);
    files
        .iter()
        .filter(|f| f.file_name().is_some_and(|n| n != "tests.rs"))
        .map(|f| {
            f.strip_prefix(dir)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect()
}

/// What a folder's paragraph gets wrong against the folder: files it names
/// that are not there, and files there it does not name (`mod.rs` may go
/// unnamed: the folder's name stands for it).
fn map_errors(
    folder: &str,
    paragraph: &str,
    files: &std::collections::BTreeSet<String>,
) -> Vec<String> {
    let named = named_files(paragraph);
    let mut errors: Vec<String> = named
        .difference(files)
        .map(|f| format!("{folder}{f} is named but not in the tree"))
        .collect();
    errors.extend(
        files
            .difference(&named)
            .filter(|f| f.as_str() != "mod.rs")
            .map(|f| format!("{folder}{f} is in the tree but not in the map")),
    );
    errors
}

#[test]
fn the_developers_map_is_the_tree() {
    let doc = std::fs::read_to_string(root().join("docs/developers.md")).unwrap();
    let layout = &doc[doc
        .find("## Layout")
        .expect("developers.md has a Layout section")..];
    let layout = &layout[..layout.find("\n## ").unwrap_or(layout.len())];
    let block = layout.split("```").nth(1).expect("the layout block");
    let lib = std::fs::read_to_string(root().join("pipeline/lib.rs")).unwrap();
    let modules = lib_modules(&lib);
    let mapped = mapped_modules(block);
    let missing: Vec<&String> = modules.difference(&mapped).collect();
    assert!(
        missing.is_empty(),
        "modules the layout block leaves out: {missing:?}"
    );
    let mut errors = Vec::new();
    for folder in ["identify/", "analysis/", "run/"] {
        let paragraph = layout
            .split("\n\n")
            .find(|p| p.contains(&format!("`{folder}`")))
            .unwrap_or_else(|| panic!("no paragraph on `{folder}`"));
        let files = files_of(&root().join("pipeline").join(folder));
        errors.extend(map_errors(folder, paragraph, &files));
    }
    assert!(
        errors.is_empty(),
        "docs/developers.md's map:\n{}",
        errors.join("\n")
    );
}

/// The map check finds a file named but gone, and a file there but not
/// named; `mod.rs` may go unnamed.
#[test]
fn the_map_check_can_fail() {
    let files: std::collections::BTreeSet<String> =
        ["mod.rs", "a.rs", "b/c.rs"].map(String::from).into();
    let paragraph = "`x/` holds `a.rs` and `gone.rs`.";
    let errors = map_errors("x/", paragraph, &files);
    assert_eq!(
        errors,
        [
            "x/gone.rs is named but not in the tree",
            "x/b/c.rs is in the tree but not in the map"
        ]
    );
    assert!(map_errors("x/", "`a.rs`, `b/c.rs`", &files).is_empty());
    let block =
        "pipeline/   the crate:\n    cli   args\n    fft poly\n              words\nscripts/  x";
    assert_eq!(
        mapped_modules(block),
        ["cli", "fft", "poly"].map(String::from).into()
    );
}
