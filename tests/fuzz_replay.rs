//! The fuzz targets' inputs replayed on the stable toolchain:
//! every file under `fuzz/corpus/<target>/` (the seeds) and
//! `fuzz/regressions/<target>/` (inputs that once crashed a reader) goes
//! through the same target body the fuzzer runs (`fuzz/src/targets.rs`).
//! None may panic, and every seed must read cleanly, so the seeds reach the
//! readers' ends. Running the fuzzers themselves needs nightly (docs/developers.md).

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

/// Every numeric key of the paper's campaign and of a small campaign with
/// logs, each set in turn to the ends of f64's range (and i64's, for an
/// integer key), then analysed: an answer or a
/// refusal, never a panic. The fuzz target `manifest_numbers` draws the
/// same edits at random, several at once.
#[test]
fn no_finite_number_in_a_manifest_panics() {
    use rayon::prelude::*;
    use std::path::PathBuf;
    targets::let_caught_panics_unwind();
    const FLOATS: [f64; 12] = [
        f64::MAX,
        -f64::MAX,
        1e300,
        -1e300,
        1e20,
        -1e20,
        1e-20,
        1e-300,
        -1e-300,
        5e-324,
        0.0,
        -0.0,
    ];
    const INTEGERS: [i64; 7] = [i64::MAX, i64::MIN, 1 << 53, -1, 0, 1, 3];
    let (logs, logs_path) = targets::numbers_campaign();
    let templates: [(&str, &str, PathBuf); 2] = [
        (
            "paper",
            targets::PAPER,
            root().join("experiments/maghareh2018/paper.toml"),
        ),
        ("logs", logs.as_str(), logs_path.clone()),
    ];
    let mut cases = Vec::new();
    for (name, text, path) in &templates {
        for (range, integer) in targets::numeric_literals(text) {
            let values: Vec<String> = if integer {
                INTEGERS.iter().map(i64::to_string).collect()
            } else {
                FLOATS.iter().map(|v| targets::toml_float(*v)).collect()
            };
            let line = text[..range.start].lines().count();
            for v in values {
                cases.push((*name, *text, path, line, range.clone(), v));
            }
        }
    }
    // A hang is a failure too (the eigenvalues' balancing once
    // had one): a watchdog names the cases still in flight after five
    // minutes (the whole set takes seconds) and ends the test binary.
    let in_flight = std::sync::Mutex::new(std::collections::BTreeSet::new());
    let done = std::sync::atomic::AtomicBool::new(false);
    let failures: Vec<String> = std::thread::scope(|scope| {
        scope.spawn(|| {
            let start = std::time::Instant::now();
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                if start.elapsed() > std::time::Duration::from_secs(300) {
                    eprintln!("hung: {:#?}", in_flight.lock().unwrap());
                    std::process::exit(101);
                }
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
        });
        let failures = cases
            .par_iter()
            .filter_map(|(name, text, path, line, range, v)| {
                let case = format!("{name} line {line}: {} -> {v}", &text[range.clone()]);
                in_flight.lock().unwrap().insert(case.clone());
                let edited = targets::with_numbers(text, vec![(range.clone(), v.clone())]);
                let panicked =
                    std::panic::catch_unwind(|| targets::analyse_text(&edited, path)).is_err();
                in_flight.lock().unwrap().remove(&case);
                panicked.then(|| format!("{case}: panicked"))
            })
            .collect();
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        failures
    });
    eprintln!("{} manifests with an extreme number analysed", cases.len());
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
