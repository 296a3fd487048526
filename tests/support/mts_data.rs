//! Where the real MTS logs are, for the unit tests in `pipeline/` and the
//! integration tests alike (each includes this file with `#[path]`): the
//! logs are not part of the repository.

use std::path::{Path, PathBuf};

/// The folder of real MTS logs (`utfsm-mts-mrdamper/`, holding 0A.txt and
/// 1A.txt): under `$SERVOID_SHARED_DATA`, else `../shared/data` beside the
/// checkout `root`, one level further up (a worktree), or
/// `/work/shared/data`. None, after a SKIPPED line on stderr, where none
/// holds them; with `SERVOID_REQUIRE_MTS_DATA` set (`.ci/run` sets it) their
/// absence fails the test instead.
pub fn mts_data_in(root: &Path) -> Option<PathBuf> {
    let candidates: Vec<PathBuf> = std::env::var_os("SERVOID_SHARED_DATA")
        .map(PathBuf::from)
        .into_iter()
        .chain([
            root.join("../shared/data"),
            root.join("../../shared/data"),
            PathBuf::from("/work/shared/data"),
        ])
        .collect();
    let found = candidates
        .iter()
        .map(|d| d.join("utfsm-mts-mrdamper"))
        .find(|d| d.join("0A.txt").exists() && d.join("1A.txt").exists());
    if found.is_none() {
        let why = format!(
            "the MTS logs are not in any of {candidates:?} (set SERVOID_SHARED_DATA to the folder holding utfsm-mts-mrdamper/)"
        );
        const REQUIRE: &str = "SERVOID_REQUIRE_MTS_DATA";
        if std::env::var_os(REQUIRE).is_some_and(|v| v != "0") {
            panic!("{REQUIRE} is set but the MTS-log tests cannot run here: {why}");
        }
        // Straight to stderr: the harness hides `eprintln!` of a passing
        // test, and a skip must be seen.
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr().lock(),
            "SKIPPED: the MTS-log tests: {why}; set {REQUIRE}=1 to make this a failure"
        );
    }
    found
}
