//! The shape of the code, checked: every module header under `pipeline/`
//! fits on a screen (at most `MAX_HEADER_LINES` lines of `//!`). A header
//! says what the module does, its entry points and the paper's equations;
//! derivations and evidence live in docs/methods.md, measurements in
//! docs/accuracy.md.

use std::path::{Path, PathBuf};

use crate::util::root;

/// The most `//!` lines a module header may have: a screen.
const MAX_HEADER_LINES: usize = 15;

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
