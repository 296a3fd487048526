//! The fuzz targets' inputs replayed on the stable toolchain (issue 15):
//! every file under `fuzz/corpus/<target>/` (the seeds) and
//! `fuzz/regressions/<target>/` (inputs that once crashed a reader) goes
//! through the same target body the fuzzer runs (`fuzz/src/targets.rs`).
//! None may panic, and every seed must read cleanly, so the seeds reach the
//! readers' ends. Running the fuzzers themselves needs nightly (README).

#[path = "../fuzz/src/targets.rs"]
mod targets;

use crate::util::root;

#[test]
fn fuzz_seeds_and_regressions_replay_without_a_panic() {
    // As the fuzz targets do: the panics servoid catches inside polars are
    // not printed.
    targets::let_caught_panics_unwind();
    let mut failures = Vec::new();
    let mut replayed = 0;
    for (name, target) in targets::TARGETS {
        let mut seeds = 0;
        for kind in ["corpus", "regressions"] {
            let dir = root().join("fuzz").join(kind).join(name);
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            let mut files: Vec<_> = entries.map(|e| e.unwrap().path()).collect();
            files.sort();
            for file in files {
                let bytes = std::fs::read(&file).unwrap();
                let shown = file.strip_prefix(root()).unwrap().display().to_string();
                match std::panic::catch_unwind(|| target(&bytes)) {
                    Err(_) => failures.push(format!("{shown}: panicked")),
                    Ok(false) if kind == "corpus" => {
                        failures.push(format!("{shown}: a seed that does not read cleanly"))
                    }
                    Ok(_) => {}
                }
                replayed += 1;
                seeds += usize::from(kind == "corpus");
            }
        }
        if seeds == 0 {
            failures.push(format!("fuzz/corpus/{name}: no seed"));
        }
    }
    eprintln!("{replayed} fuzz inputs replayed");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
