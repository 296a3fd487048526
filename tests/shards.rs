//! Scale-out: `servoid run --shard i/n` shares out the per-log work and
//! `servoid merge` puts the shares together into exactly what one run over
//! all the logs writes; shards that do not belong together are refused.
//! (The same on a real Slurm cluster: scripts/slurm-shards.sh.)

use std::path::{Path, PathBuf};

use crate::util::{bundled_simulation, outputs, root, scratch, servoid, servoid_into};

/// The bundled default simulated into `dir/sim`, without its Monte Carlo
/// (see `util::bundled_simulation`); its analysis manifest.
pub fn campaign(dir: &Path) -> PathBuf {
    simulated(dir, false)
}

/// The bundled default simulated into `dir/sim` as it is bundled, Monte
/// Carlo and all; its analysis manifest.
pub fn bundled_campaign(dir: &Path) -> PathBuf {
    simulated(dir, true)
}

fn simulated(dir: &Path, monte_carlo: bool) -> PathBuf {
    let o = servoid_into(
        dir,
        "simulate",
        &bundled_simulation(dir, monte_carlo),
        &dir.join("sim"),
        &["--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    dir.join("sim/campaign.toml")
}

fn shard(dir: &Path, manifest: &Path, i: usize, n: usize) -> PathBuf {
    shard_into(dir, manifest, (i, n), &format!("shard-{i}"), &[])
}

/// Share `i` of `n` of the campaign run into `dir/name`, with `extra`
/// arguments.
fn shard_into(
    dir: &Path,
    manifest: &Path,
    (i, n): (usize, usize),
    name: &str,
    extra: &[&str],
) -> PathBuf {
    let out = dir.join(name);
    let share = format!("{i}/{n}");
    let mut args = vec!["--shard", &share, "--quiet"];
    args.extend(extra);
    let o = servoid_into(dir, "run", manifest, &out, &args);
    assert_eq!(o.code, 0, "{}", o.stderr);
    out
}

fn merge(dir: &Path, shards: &[&Path], out: &str) -> crate::util::Output {
    let mut args = vec!["merge"];
    args.extend(shards.iter().map(|s| s.to_str().unwrap()));
    let out = dir.join(out);
    args.extend(["--out", out.to_str().unwrap(), "--log-format", "json"]);
    servoid(dir, &args)
}

#[test]
fn three_shards_merge_into_the_bytes_of_one_run() {
    let dir = scratch();
    // With its Monte Carlo, which the first shard alone runs and the merge
    // finds in that shard's cache.
    let manifest = bundled_campaign(dir.path());
    let single = dir.path().join("single");
    let o = servoid_into(dir.path(), "run", &manifest, &single, &["--quiet"]);
    assert_eq!(o.code, 0);
    // Each shard has the three identification runs and every third of the
    // four validation runs.
    let shards: Vec<PathBuf> = (0..3).map(|i| shard(dir.path(), &manifest, i, 3)).collect();
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(shards[1].join("shard.json")).unwrap()).unwrap();
    assert_eq!(
        info["runs"],
        serde_json::json!(["no-specimen", "spring-k1", "spring-k2", "exp2"])
    );
    // The Monte Carlo is the first shard's alone: its cache holds it.
    let mc = |d: &Path| -> bool {
        std::fs::read_dir(d.join(".cache/runs"))
            .unwrap()
            .flatten()
            .any(|e| {
                let packed = std::fs::read(e.path()).unwrap();
                let text = String::from_utf8(zstd::decode_all(packed.as_slice()).unwrap()).unwrap();
                text.contains("\"excitation_run\"") && text.contains("\"agreement\"")
            })
    };
    assert_eq!(
        shards.iter().map(|d| mc(d)).collect::<Vec<_>>(),
        [true, false, false]
    );
    // Given in any order.
    let o = merge(dir.path(), &[&shards[2], &shards[0], &shards[1]], "merged");
    assert_eq!(o.code, 0, "{}", o.stderr);
    let summary: serde_json::Value =
        serde_json::from_str(o.stdout.lines().last().unwrap()).unwrap();
    assert_eq!(summary["cached"], 7, "the merge does no per-log work");
    let (a, b) = (outputs(&single), outputs(&dir.path().join("merged")));
    let names = |t: &[(String, Vec<u8>)]| t.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&a), names(&b));
    assert!(a.len() > 40, "results, pages, figures, tables, history");
    for ((name, x), (_, y)) in a.iter().zip(&b) {
        assert!(
            x == y,
            "{name} differs between one run and the merged shards"
        );
    }
}

#[test]
fn shards_that_do_not_belong_together_are_refused() {
    let dir = scratch();
    let manifest = campaign(dir.path());
    let s0 = shard(dir.path(), &manifest, 0, 2);
    let s1 = shard(dir.path(), &manifest, 1, 2);
    let refused = |shards: &[&Path], want: &str| {
        let o = merge(dir.path(), shards, "refused");
        assert_eq!(o.code, 2, "{}", o.stderr);
        assert!(o.stderr.contains(want), "missing {want:?} in {}", o.stderr);
        assert!(!dir.path().join("refused").exists(), "nothing written");
    };
    refused(&[&s0], "shards [1] of 2 are missing");
    refused(&[&s0, &s0], "shard 0/2 is given twice");
    refused(
        &[&dir.path().join("sim")],
        "not a shard folder (no shard.json)",
    );
    // Another campaign's shard.
    let other = dir.path().join("paper-shard");
    let o = servoid_into(
        dir.path(),
        "run",
        &root().join("experiments/maghareh2018/paper.toml"),
        &other,
        &["--shard", "1/2", "--quiet"],
    );
    assert_eq!(o.code, 0);
    refused(&[&s0, &other], "a shard of another campaign");
    // Another servoid's shard.
    let info = s1.join("shard.json");
    let text = std::fs::read_to_string(&info).unwrap();
    std::fs::write(&info, text.replace(env!("CARGO_PKG_VERSION"), "0.0.1")).unwrap();
    refused(&[&s0, &s1], "a shard of another servoid version (0.0.1;");
}

/// A night's `--date` goes with its shards: each records it, the merge
/// gives it to the history's entry as one run would, and shards of two
/// dates, or a merge asked for another, are refused before anything is
/// written.
#[test]
fn a_nights_date_goes_through_its_shards_into_the_history() {
    use servoid::ingest::{TableFormat, read_table};
    let dir = scratch();
    let manifest = campaign(dir.path());
    let dated = |i: usize, date: &str| -> PathBuf {
        let name = format!("shard-{i}-{date}");
        shard_into(dir.path(), &manifest, (i, 2), &name, &["--date", date])
    };
    let (s0, s1) = (dated(0, "2026-11-02"), dated(1, "2026-11-02"));
    let o = merge(dir.path(), &[&s0, &s1], "merged");
    assert_eq!(o.code, 0, "{}", o.stderr);
    let history = read_table(
        &dir.path().join("merged/history.parquet"),
        TableFormat::Parquet,
    )
    .unwrap();
    let k = history.column("date").expect("a date column");
    assert_eq!(history.rows.len(), 1);
    assert_eq!(history.rows[0][k].as_deref(), Some("2026-11-02"));

    let other = dated(1, "2026-11-03");
    let o = merge(dir.path(), &[&s0, &other], "two-dates");
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(o.stderr.contains("--date"), "{}", o.stderr);
    assert!(!dir.path().join("two-dates").exists());
    let out = dir.path().join("asked");
    let o = servoid(
        dir.path(),
        &[
            "merge",
            s0.to_str().unwrap(),
            s1.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--date",
            "2026-11-03",
        ],
    );
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr
            .contains("the shards were run with --date 2026-11-02"),
        "{}",
        o.stderr
    );
    assert!(!out.exists());
}

/// With the validation runs in the joint fit the rig needs every
/// validation log, which a shard reading only its share cannot give: the
/// shard is refused as a usage error naming the key, before it writes
/// anything.
#[test]
fn a_campaign_fitting_its_validation_runs_into_the_rig_is_not_sharded() {
    let dir = scratch();
    let paper =
        std::fs::read_to_string(root().join("experiments/maghareh2018/paper.toml")).unwrap();
    let manifest = dir.path().join("paper.toml");
    std::fs::write(
        &manifest,
        format!("{paper}\n[identification.joint]\ninclude_validation = true\n"),
    )
    .unwrap();
    let out = dir.path().join("shard");
    let o = servoid_into(
        dir.path(),
        "run",
        &manifest,
        &out,
        &["--shard", "0/2", "--quiet"],
    );
    assert_eq!(o.code, 2, "{}", o.stderr);
    for want in [
        manifest.display().to_string(),
        "identification.joint.include_validation".to_string(),
        "without --shard".to_string(),
    ] {
        assert!(o.stderr.contains(&want), "missing {want:?} in {}", o.stderr);
    }
    assert!(!out.exists(), "nothing written");
    // Without --shard the same manifest runs.
    let o = servoid_into(dir.path(), "run", &manifest, &out, &["--quiet"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
}

/// A merge draws what its shards drew (with another `--figures`
/// it redid every run's log work, silently, as the figure choice is in
/// each run's cache key): by default the shards' choice, and another is
/// refused naming both. `--shard` is not a merge's (it was accepted and
/// ignored), and a manifest that moved with its logs is found with
/// `--manifest`, which the message names.
#[test]
fn a_merge_draws_what_the_shards_drew_and_finds_a_moved_manifest() {
    let dir = scratch();
    let manifest = campaign(dir.path());
    let run_shard = |i: usize| {
        let out = dir.path().join(format!("png-{i}"));
        let o = servoid_into(
            dir.path(),
            "run",
            &manifest,
            &out,
            &["--shard", &format!("{i}/2"), "--figures", "png", "--quiet"],
        );
        assert_eq!(o.code, 0, "{}", o.stderr);
        out
    };
    let (s0, s1) = (run_shard(0), run_shard(1));
    let merge_with = |extra: &[&str], out: &str| {
        let mut args = vec!["merge", s0.to_str().unwrap(), s1.to_str().unwrap()];
        args.extend(["--out", out, "--log-format", "json"]);
        args.extend_from_slice(extra);
        servoid(dir.path(), &args)
    };
    let summary = |stdout: &str| -> serde_json::Value {
        serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
    };

    let o = merge_with(&["--figures", "all"], "refused");
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains("the shards drew their figures with --figures png, and each run's cached outcome is for those: merge with --figures png (the default)"),
        "{}",
        o.stderr
    );
    assert!(!dir.path().join("refused").exists());
    let o = merge_with(&["--shard", "0/2"], "refused");
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains("unexpected argument '--shard'"),
        "{}",
        o.stderr
    );

    // The default: the shards' PNGs, every run from their caches.
    let o = merge_with(&[], "merged");
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(summary(&o.stdout)["cached"], 7, "{}", o.stdout);
    let figures: Vec<String> = std::fs::read_dir(dir.path().join("merged/figures"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !figures.is_empty() && figures.iter().all(|f| f.ends_with(".png")),
        "{figures:?}"
    );
    let rig = |out: &str| -> serde_json::Value {
        let r: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.path().join(out).join("results.json")).unwrap(),
        )
        .unwrap();
        r["rig"].clone()
    };

    // The campaign's folder moved (the merge on another machine).
    std::fs::rename(dir.path().join("sim"), dir.path().join("moved")).unwrap();
    let o = merge_with(&[], "refused");
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains(&format!(
            "{}: the manifest the shards ran is not there (",
            manifest.display()
        )) && o.stderr.contains("if it moved, give it with --manifest"),
        "{}",
        o.stderr
    );
    let moved = dir.path().join("moved/campaign.toml");
    let o = merge_with(&["--manifest", moved.to_str().unwrap()], "merged-moved");
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(summary(&o.stdout)["cached"], 7, "{}", o.stdout);
    assert_eq!(rig("merged-moved"), rig("merged"));
}

/// Two shards given the same `--out`: the second replaced the first
/// without a word, and the merge then said a shard was missing without
/// saying why. The second is refused (exit 2, naming the shard the folder
/// holds), the folder keeps the first, and the first may run again there.
#[test]
fn two_shards_into_one_folder_are_refused() {
    let dir = scratch();
    let d = dir.path();
    let manifest = campaign(d);
    let out = d.join("shared");
    let shard_into = |i: &str| {
        servoid_into(
            d,
            "run",
            &manifest,
            &out,
            &["--shard", i, "--quiet", "--figures", "none"],
        )
    };
    let first = shard_into("0/2");
    assert_eq!(first.code, 0, "{}", first.stderr);
    let second = shard_into("1/2");
    assert_eq!(second.code, 2, "{}", second.stderr);
    assert!(
        second.stderr.contains("holds shard 0/2 of campaign `maghareh2018-synthetic`, which this run of shard 1/2 would replace")
            && second.stderr.contains("give each shard its own --out"),
        "{}",
        second.stderr
    );
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("shard.json")).unwrap()).unwrap();
    assert_eq!(info["shard"]["index"], 0);
    let again = shard_into("0/2");
    assert_eq!(again.code, 0, "{}", again.stderr);
}
