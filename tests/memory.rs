//! Memory on one very long log: a CSV log of over 1 GB is
//! analysed, figures and all, in at most twice its size.
//!
//! The log is the bundled simulation's no-specimen run made 7,000 s long
//! (14.3 M rows at 2,048 Hz, 1.1 GB). The peak is the kernel's count for
//! that one process: the maximum resident set size wait4(2) returns for it.

use std::process::Command;

use crate::util::{bundled_simulation, run_by_id, scratch, servoid_into};

#[test]
// The child is reaped by wait4 below, which also gives its peak memory.
#[allow(clippy::zombie_processes)]
fn a_csv_log_over_1_gb_is_analysed_in_at_most_twice_its_size() {
    let dir = scratch();
    let text = std::fs::read_to_string(bundled_simulation(dir.path(), false)).unwrap();
    let sweep = "duration_s = 170.0";
    assert!(text.contains(sweep), "the bundled sweep lasts 170 s");
    let text = text.replace(sweep, "duration_s = 7000.0");
    // The first run only: the no-specimen run.
    let first = text.find("[[runs]]").unwrap();
    let second = first + 1 + text[first + 1..].find("[[runs]]").unwrap();
    let sim = dir.path().join("long.toml");
    std::fs::write(&sim, &text[..second]).unwrap();
    let o = servoid_into(
        dir.path(),
        "simulate",
        &sim,
        &dir.path().join("sim"),
        &["--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let log = dir.path().join("sim/logs/no-specimen.csv");
    let size = std::fs::metadata(&log).unwrap().len();
    assert!(size > 1_000_000_000, "the log is over 1 GB: {size} bytes");

    let child = Command::new(env!("CARGO_BIN_EXE_servoid"))
        .arg("run")
        .arg(dir.path().join("sim/campaign.toml"))
        .arg("--out")
        .arg(dir.path().join("out"))
        .arg("--quiet")
        .current_dir(dir.path())
        .spawn()
        .unwrap();
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value for wait4 to fill.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: waits for our own child, whose pid this is, once; status and
    // usage are valid for writes.
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    assert_eq!(pid, child.id() as libc::pid_t);
    assert!(
        libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0,
        "servoid run: wait status {status}"
    );
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("out/results.json")).unwrap())
            .unwrap();
    assert_eq!(run_by_id(&results, "no-specimen")["status"], "ok");

    // ru_maxrss is in kilobytes on Linux.
    let peak = usage.ru_maxrss as u64 * 1024;
    eprintln!(
        "a {:.2} GB CSV log: peak RSS {:.2} GB ({:.2} times the file)",
        size as f64 / 1e9,
        peak as f64 / 1e9,
        peak as f64 / size as f64
    );
    assert!(
        peak <= 2 * size,
        "peak RSS {peak} bytes for a log of {size} bytes"
    );
}
