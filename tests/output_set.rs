//! Outputs as a set: a rerun killed with SIGKILL at any point
//! leaves the output folder holding the previous run's files, byte for
//! byte, or the new run's, never a mix; the next run completes and removes
//! what the killed one left behind.
//!
//! The kills are real SIGKILLs: at named points where a mix was most
//! likely before (`SERVOID_KILL_AT`, see `report/output_folder.rs`: after the work
//! folder is filled, after results.json, just before and just after the
//! exchange), and from outside at fractions of the rerun's own duration.

use std::collections::BTreeMap;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::shards::campaign;
use crate::util::{scratch, servoid_into, tree};

type Tree = BTreeMap<String, Vec<u8>>;

/// A tree without run.jsonl, the one file whose bytes hold wall-clock
/// times.
fn timeless(mut t: Tree) -> Tree {
    t.remove("run.jsonl");
    t
}

/// What a job left that is not an output: work folders beside `out` and
/// per-file temporaries inside it.
fn leftovers(out: &Path) -> Vec<String> {
    let name = out.file_name().unwrap().to_string_lossy().into_owned();
    let beside = std::fs::read_dir(out.parent().unwrap())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&format!(".{name}.")))
        // The output folder's lock file stays by design (removing it would
        // let a waiting job lock a file no later job sees).
        .filter(|n| *n != format!(".{name}.servoid-lock"));
    let inside = tree(out)
        .into_keys()
        .filter(|p| p.contains(".tmp-") || p.contains(".servoid-probe-"));
    beside.chain(inside).collect()
}

fn copy_tree(from: &Path, to: &Path) {
    let _ = std::fs::remove_dir_all(to);
    let o = Command::new("cp")
        .arg("-a")
        .arg(from)
        .arg(to)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The rerun: manifest B into `out`, killed at `point` when given.
fn rerun(dir: &Path, manifest: &Path, out: &Path, point: Option<&str>) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_servoid"));
    c.arg("run")
        .arg(manifest)
        .arg("--out")
        .arg(out)
        .args(["--figures", "png", "--quiet"])
        .current_dir(dir);
    match point {
        Some(p) => c.env("SERVOID_KILL_AT", p),
        None => c.env_remove("SERVOID_KILL_AT"),
    };
    c
}

#[test]
fn a_rerun_killed_at_any_point_leaves_the_previous_set_or_the_new_one() {
    let dir = scratch();
    let manifest_a = campaign(dir.path());
    // The same campaign under a changed manifest: its SHA-256 is in
    // results.json and on the page, so the two sets differ in what a
    // reader opens first, while the cache (keyed by run) is shared.
    let manifest_b: PathBuf = dir.path().join("sim/campaign-b.toml");
    let text = std::fs::read_to_string(&manifest_a).unwrap();
    std::fs::write(&manifest_b, format!("{text}\n# the rerun's manifest\n")).unwrap();

    let out = dir.path().join("out");
    let o = servoid_into(
        dir.path(),
        "run",
        &manifest_a,
        &out,
        &["--figures", "png", "--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let pristine = dir.path().join("pristine");
    copy_tree(&out, &pristine);
    let old = tree(&out);
    assert!(old.contains_key("results.json") && old.contains_key("report.html"));

    // The new set, from an uninterrupted rerun over a copy of the old.
    let reference = dir.path().join("reference");
    copy_tree(&pristine, &reference);
    let clock = Instant::now();
    let status = rerun(dir.path(), &manifest_b, &reference, None)
        .status()
        .unwrap();
    let took = clock.elapsed();
    assert!(status.success());
    let new = timeless(tree(&reference));
    assert_ne!(old["results.json"], new["results.json"]);
    assert_ne!(old["report.html"], new["report.html"]);

    let is_old = |t: &Tree| *t == old;
    let is_new = |t: &Tree| timeless(t.clone()) == new;

    // At the named points: before the exchange the folder is the old set
    // to the byte; after it, the new one.
    for (point, expect_new) in [
        ("carried", false),
        ("results", false),
        ("exchange", false),
        ("exchanged", true),
    ] {
        copy_tree(&pristine, &out);
        let status = rerun(dir.path(), &manifest_b, &out, Some(point))
            .status()
            .unwrap();
        assert_eq!(status.signal(), Some(9), "killed at {point}");
        let now = tree(&out);
        if expect_new {
            assert!(is_new(&now), "killed at {point}: not the new set");
        } else {
            assert!(is_old(&now), "killed at {point}: the old set changed");
        }
    }

    // From outside, at fractions of the rerun's duration. A kill that
    // comes after the job ended finds the new set, which is as good.
    let mut outcomes = Vec::new();
    for k in 1..=5u32 {
        copy_tree(&pristine, &out);
        let mut child = rerun(dir.path(), &manifest_b, &out, None).spawn().unwrap();
        std::thread::sleep(took * k / 6);
        let _ = child.kill();
        let status = child.wait().unwrap();
        let now = tree(&out);
        let (o, n) = (is_old(&now), is_new(&now));
        assert!(o || n, "killed at {k}/6 of the run: a mix of the two sets");
        outcomes.push((status.signal(), if o { "old" } else { "new" }));
    }
    eprintln!("kills from outside (signal, set found): {outcomes:?}");
    assert!(
        outcomes.iter().any(|(s, _)| *s == Some(9)),
        "no kill landed while the rerun ran: {outcomes:?} in {took:?}"
    );

    // A temporary an older job left inside the folder, and the folder a
    // job killed after its exchange left beside it, are gone after the
    // next run, which completes with the new set.
    std::fs::write(out.join("figures/.exp1.png.tmp-77"), b"half").unwrap();
    assert!(!leftovers(&out).is_empty());
    let status = rerun(dir.path(), &manifest_b, &out, None).status().unwrap();
    assert!(status.success());
    let after = timeless(tree(&out));
    let differing: Vec<&String> = after
        .keys()
        .chain(new.keys())
        .filter(|k| after.get(*k) != new.get(*k))
        .collect();
    assert!(
        differing.is_empty(),
        "the next run's set differs in {differing:?}"
    );
    assert_eq!(leftovers(&out), Vec::<String>::new());
}

#[test]
fn a_failed_rerun_replaces_nothing_and_says_where_it_could_not_write() {
    let dir = scratch();
    let manifest = campaign(dir.path());
    let out = dir.path().join("out");
    let o = servoid_into(
        dir.path(),
        "run",
        &manifest,
        &out,
        &["--figures", "none", "--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    // A folder where a figure must go: the write fails mid-run. (It
    // holds a file, so that the tree below sees it.)
    let blocker = out.join("figures/frf-no-specimen.png");
    std::fs::create_dir_all(&blocker).unwrap();
    std::fs::write(blocker.join("keep"), b"").unwrap();
    let before = tree(&out);
    let o = servoid_into(dir.path(), "run", &manifest, &out, &["--force", "--quiet"]);
    assert_eq!(o.code, 1, "{}", o.stderr);
    assert!(
        o.stderr.contains(&format!("{}/figures/", out.display())),
        "the error names the output folder, not a work folder: {}",
        o.stderr
    );
    assert!(!o.stderr.contains(".servoid-"), "{}", o.stderr);
    assert_eq!(tree(&out), before, "the previous set is untouched");
    assert_eq!(leftovers(&out), Vec::<String>::new());
}

fn args(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// The campaigns named in the history table at `out`, in table order.
fn history_campaigns(out: &Path) -> Vec<String> {
    let t = servoid::ingest::read_table(
        &out.join("history.parquet"),
        servoid::ingest::TableFormat::Parquet,
    )
    .unwrap();
    let c = t.column("campaign").unwrap();
    t.rows.iter().map(|r| r[c].clone().unwrap()).collect()
}

/// Until the lock file names `pid` as its holder (its first line).
fn wait_for_holder(lock: &Path, pid: u32, start: Instant) {
    while std::fs::read_to_string(lock)
        .ok()
        .and_then(|t| t.lines().next().map(str::to_string))
        != Some(pid.to_string())
    {
        assert!(start.elapsed().as_secs() < 120, "job A never took the lock");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Job A holds the output folder `out`'s lock (paused 15 s just after
/// taking it); job B starts once A's pid is in the lock file (A has it),
/// into the same folder. The pause is long enough for B to load its
/// manifest and reach the lock on a loaded two-core machine. Both must
/// succeed. Returns A's pid and both outputs.
fn two_jobs(
    dir: &Path,
    out: &Path,
    a: &[&str],
    b: &[&str],
) -> (u32, std::process::Output, std::process::Output) {
    let first = Command::new(env!("CARGO_BIN_EXE_servoid"))
        .args(a)
        .current_dir(dir)
        .env("SERVOID_PAUSE_AT", "locked")
        .env("SERVOID_PAUSE_MS", "15000")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = first.id();
    let name = out.file_name().unwrap().to_string_lossy();
    let lock = out.with_file_name(format!(".{name}.servoid-lock"));
    let start = Instant::now();
    wait_for_holder(&lock, pid, start);
    let second = Command::new(env!("CARGO_BIN_EXE_servoid"))
        .args(b)
        .current_dir(dir)
        .env_remove("SERVOID_PAUSE_AT")
        .output()
        .unwrap();
    let first = first.wait_with_output().unwrap();
    for job in [&first, &second] {
        assert!(
            job.status.success(),
            "{}",
            String::from_utf8_lossy(&job.stderr)
        );
    }
    (pid, first, second)
}

/// Two jobs into one output folder at once: before,
/// both carried the same previous set and the later one's exchange dropped
/// the earlier one's history entry, both exiting 0. Now the second waits
/// for the first's lock, says so on stderr naming the first's pid, and
/// starts from the set the first put in place: the history holds both
/// entries. Run + run, then run + merge. A lock left by a killed job
/// blocks nothing: the kernel releases it with the process.
#[test]
fn two_jobs_into_one_folder_take_turns_and_keep_both_history_entries() {
    let dir = scratch();
    let d = dir.path();
    let manifest = campaign(d);
    let text = std::fs::read_to_string(&manifest).unwrap();
    let named = |name: &str| {
        let path = d.join(format!("sim/{name}.toml"));
        let key = "[campaign]\nname = \"";
        let at = text.find(key).expect("a campaign name") + key.len();
        std::fs::write(&path, format!("{}{name}-{}", &text[..at], &text[at..])).unwrap();
        path
    };
    let (a, b, c) = (named("a"), named("b"), named("c"));
    let out = d.join("night");
    let run = |m: &Path| -> Vec<String> {
        [
            "run",
            m.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ]
        .map(String::from)
        .to_vec()
    };
    let (ra, rb) = (run(&a), run(&b));

    let (pid, _, second) = two_jobs(d, &out, &args(&ra), &args(&rb));
    let said = String::from_utf8_lossy(&second.stderr);
    assert!(
        said.contains(&format!(
            "is being written by another job (pid {pid}, `{} run ",
            env!("CARGO_BIN_EXE_servoid")
        )) && said.contains("waiting up to 1800 s for it to finish (--wait)"),
        "{said}"
    );
    let names = history_campaigns(&out);
    assert_eq!(names.len(), 2, "{names:?}");
    assert!(
        names[0].starts_with("a-") && names[1].starts_with("b-"),
        "{names:?}"
    );
    assert!(leftovers(&out).is_empty(), "{:?}", leftovers(&out));

    // Run + merge: campaign c's two shards merged into the folder while a
    // rerun of a holds it.
    let shards: Vec<PathBuf> = (0..2)
        .map(|i| {
            let s = d.join(format!("shard-{i}"));
            let o = servoid_into(d, "run", &c, &s, &["--shard", &format!("{i}/2"), "--quiet"]);
            assert_eq!(o.code, 0, "{}", o.stderr);
            s
        })
        .collect();
    let mut merge = vec!["merge".to_string()];
    merge.extend(shards.iter().map(|s| s.to_str().unwrap().to_string()));
    merge.extend(["--out", out.to_str().unwrap(), "--quiet"].map(String::from));
    let (_, _, second) = two_jobs(d, &out, &args(&ra), &args(&merge));
    assert!(String::from_utf8_lossy(&second.stderr).contains("for it to finish (--wait)"));
    let names = history_campaigns(&out);
    assert_eq!(names.len(), 3, "{names:?}");
    assert!(names[2].starts_with("c-"), "{names:?}");

    // A job killed while it holds the lock leaves the lock file, unlocked.
    let killed = Command::new(env!("CARGO_BIN_EXE_servoid"))
        .args(args(&rb))
        .current_dir(d)
        .env("SERVOID_KILL_AT", "locked")
        .output()
        .unwrap();
    assert_eq!(killed.status.signal(), Some(9));
    let o = servoid_into(d, "run", &b, &out, &["--quiet"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(!o.stderr.contains("waiting"), "{}", o.stderr);
}

/// A job stopped (SIGSTOP) while it holds the output folder would make
/// every later job wait forever. A later job waits `--wait` seconds, then
/// gives up with exit 2, naming the holder's pid and command and saying it
/// is stopped; the holder, continued, finishes its set.
#[test]
fn a_stopped_holder_is_waited_for_then_named() {
    let dir = scratch();
    let d = dir.path();
    let manifest = campaign(d);
    let out = d.join("night");
    let m = manifest.to_str().unwrap();
    let o = out.to_str().unwrap();
    let holder = Command::new(env!("CARGO_BIN_EXE_servoid"))
        .args(["run", m, "--out", o, "--quiet"])
        .current_dir(d)
        .env("SERVOID_PAUSE_AT", "locked")
        .env("SERVOID_PAUSE_MS", "3000")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = holder.id();
    let lock = out.with_file_name(".night.servoid-lock");
    wait_for_holder(&lock, pid, Instant::now());
    let signal = |sig: &str| {
        let done = Command::new("kill")
            .args([sig, &pid.to_string()])
            .status()
            .unwrap();
        assert!(done.success(), "kill {sig} {pid}");
    };
    signal("-STOP");
    let clock = Instant::now();
    let waiter = servoid_into(d, "run", &manifest, &out, &["--quiet", "--wait", "2"]);
    let waited = clock.elapsed();
    signal("-CONT");
    assert_eq!(waiter.code, 2, "{}", waiter.stderr);
    assert!(waited.as_secs_f64() >= 2.0, "gave up after {waited:?}");
    for words in [
        format!(
            "(pid {pid}, `{} run {m} --out {o} --quiet`",
            env!("CARGO_BIN_EXE_servoid")
        ),
        "stopped (SIGSTOP)".to_string(),
        "still holds it after 2 s (--wait)".to_string(),
    ] {
        assert!(waiter.stderr.contains(&words), "{words}: {}", waiter.stderr);
    }
    let holder = holder.wait_with_output().unwrap();
    assert!(
        holder.status.success(),
        "{}",
        String::from_utf8_lossy(&holder.stderr)
    );
    assert!(out.join("results.json").is_file());
}
