//! `--figures summary|all|png|svg|none` and the manifest's `[report]
//! figures`: which figure files a run writes, what the page shows of them,
//! and that results.json does not depend on the choice.

use std::path::Path;

use crate::util::{root, scratch, servoid, servoid_into};

/// Run paper.toml with `--figures choice`; the output folder's results.json,
/// page and figure file names.
fn run_with(dir: &Path, choice: &str) -> (Vec<u8>, String, Vec<String>) {
    let out = dir.join(choice);
    let o = servoid_into(
        dir,
        "run",
        &root().join("experiments/maghareh2018/paper.toml"),
        &out,
        &["--figures", choice, "--quiet"],
    );
    assert_eq!(o.code, 0, "--figures {choice}: {}", o.stderr);
    let mut files: Vec<String> = std::fs::read_dir(out.join("figures"))
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    (
        std::fs::read(out.join("results.json")).unwrap(),
        // minijinja escapes `/` in attributes as `&#x2f;`; the browser reads
        // both alike.
        std::fs::read_to_string(out.join("report.html"))
            .unwrap()
            .replace("&#x2f;", "/"),
        files,
    )
}

#[test]
fn each_choice_writes_its_files_and_the_page_says_what_it_has() {
    let dir = scratch();
    let (json_all, page_all, files_all) = run_with(dir.path(), "all");
    // paper.toml has published transfer functions, no logs: its one figure
    // is the stiffness sensitivity, on the campaign's page.
    assert_eq!(files_all, ["sensitivity.png", "sensitivity.svg"]);
    assert!(page_all.contains("<img src=\"figures/sensitivity.png\""));
    assert!(page_all.contains("href=\"figures/sensitivity.png\""));
    assert!(page_all.contains("href=\"figures/sensitivity.svg\""));

    let (json_png, page_png, files_png) = run_with(dir.path(), "png");
    assert_eq!(files_png, ["sensitivity.png"]);
    assert!(page_png.contains("<img src=\"figures/sensitivity.png\""));
    assert!(!page_png.contains(".svg"));

    let (json_svg, page_svg, files_svg) = run_with(dir.path(), "svg");
    assert_eq!(files_svg, ["sensitivity.svg"]);
    assert!(page_svg.contains("<img src=\"figures/sensitivity.svg\""));
    assert!(!page_svg.contains(".png"));

    let (json_none, page_none, files_none) = run_with(dir.path(), "none");
    assert!(files_none.is_empty(), "{files_none:?}");
    assert!(!page_none.contains("<figure"));
    assert!(page_none.contains("No figures were drawn for this report (--figures none)."));

    for (choice, json) in [("png", &json_png), ("svg", &json_svg), ("none", &json_none)] {
        assert!(
            json == &json_all,
            "results.json with --figures {choice} differs from --figures all"
        );
    }
}

#[test]
fn figures_without_run_and_an_unknown_choice_are_usage_errors() {
    let dir = scratch();
    let sim = root().join("experiments/maghareh2018/simulation.toml");
    let o = servoid(
        dir.path(),
        &["simulate", sim.to_str().unwrap(), "--figures", "none"],
    );
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(o.stderr.contains("--run"), "{}", o.stderr);
    let paper = root().join("experiments/maghareh2018/paper.toml");
    let o = servoid(
        dir.path(),
        &["run", paper.to_str().unwrap(), "--figures", "jpeg"],
    );
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr
            .contains("possible values: all, png, svg, summary, none"),
        "{}",
        o.stderr
    );
}

/// A run named `identification` keeps its FRF figure beside the campaign's
///: run figures are `frf-<run>`, and the campaign's was
/// `frf-identification`, which such a run overwrote. Now the campaign's is
/// `identification-frf`, and no campaign figure starts as a run's does.
#[test]
fn a_run_named_like_a_campaign_figure_keeps_both_figures() {
    let dir = scratch();
    let manifest = crate::shards::campaign(dir.path());
    let text = std::fs::read_to_string(&manifest).unwrap();
    assert!(text.contains("id = \"spring-k1\""));
    let renamed = dir.path().join("sim/renamed.toml");
    std::fs::write(
        &renamed,
        text.replace("id = \"spring-k1\"", "id = \"identification\""),
    )
    .unwrap();
    let out = dir.path().join("out");
    let o = servoid_into(
        dir.path(),
        "run",
        &renamed,
        &out,
        &["--figures", "png", "--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let figures = out.join("figures");
    assert!(figures.join("frf-identification.png").is_file());
    assert!(figures.join("identification-frf.png").is_file());
    let page = std::fs::read_to_string(out.join("report.html"))
        .unwrap()
        .replace("&#x2f;", "/");
    assert!(
        page.contains("figures/identification-frf.png"),
        "the campaign's FRF figure"
    );
    let run_page = std::fs::read_to_string(out.join("runs/identification.html"))
        .unwrap()
        .replace("&#x2f;", "/");
    assert!(
        run_page.contains("frf-identification.png"),
        "the run's own FRF figure"
    );
}

/// The files under one of servoid's own folders of `out`, sorted.
fn listed(out: &Path, folder: &str) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(out.join(folder))
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

/// A rerun into the same folder holds what this job wrote and nothing an
/// earlier job left in servoid's own folders (figures stayed
/// after `--figures none`, and a renamed run's pages, figures and tables
/// stayed beside the new ones); the lab's own files stay.
#[test]
fn a_rerun_leaves_no_figure_page_or_table_of_an_earlier_one() {
    let dir = scratch();
    let manifest = crate::shards::campaign(dir.path());
    let out = dir.path().join("out");
    let run = |manifest: &Path, choice: &str| {
        let o = servoid_into(
            dir.path(),
            "run",
            manifest,
            &out,
            &["--figures", choice, "--quiet"],
        );
        assert_eq!(o.code, 0, "--figures {choice}: {}", o.stderr);
    };
    run(&manifest, "png");
    let figures = listed(&out, "figures");
    assert!(
        figures.contains(&"frf-spring-k1.png".to_string()),
        "{figures:?}"
    );
    assert!(figures.iter().all(|f| f.ends_with(".png")), "{figures:?}");
    assert!(listed(&out, "runs").contains(&"spring-k1.html".to_string()));
    assert!(listed(&out, "tables").contains(&"frf-spring-k1.parquet".to_string()));
    std::fs::write(out.join("notes.txt"), "the lab's own").unwrap();

    // The same campaign with spring-k1 renamed: nothing of spring-k1 is
    // left, and spring-k9 has what spring-k1 had.
    let text = std::fs::read_to_string(&manifest).unwrap();
    assert!(text.contains("id = \"spring-k1\""));
    let renamed = dir.path().join("sim/renamed.toml");
    std::fs::write(
        &renamed,
        // The paper's figures by number name its figures too.
        text.replace("id = \"spring-k1\"", "id = \"spring-k9\"")
            .replace("-spring-k1\"", "-spring-k9\""),
    )
    .unwrap();
    run(&renamed, "png");
    // Sorted again after the rename. The renamed night is the same night
    // (same campaign, date and logs), so it replaces its history entry:
    // one entry, and no trend figure, which is drawn from a second on.
    let k9 = |names: Vec<String>, ext: &str| -> Vec<String> {
        let mut names: Vec<String> = names
            .into_iter()
            .map(|n| n.replace("spring-k1", "spring-k9").replace(".png", ext))
            .collect();
        names.sort();
        names
    };
    assert_eq!(listed(&out, "figures"), k9(figures.clone(), ".png"));
    for folder in ["runs", "tables"] {
        let now = listed(&out, folder);
        assert!(
            now.iter().all(|n| !n.contains("spring-k1")),
            "{folder}: {now:?}"
        );
        assert!(
            now.iter().any(|n| n.contains("spring-k9")),
            "{folder}: {now:?}"
        );
    }

    run(&renamed, "none");
    assert_eq!(listed(&out, "figures"), Vec::<String>::new());
    assert!(
        !listed(&out, "tables").is_empty(),
        "tables do not depend on --figures"
    );

    run(&renamed, "svg");
    assert_eq!(listed(&out, "figures"), k9(figures, ".svg"));
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "the lab's own"
    );
}

/// A campaign that numbers no publication's figures draws the summary's by
/// default, as PNG: each run's FRF, a validation run's time windows and the
/// campaign's own figures, the run's page saying how to draw the rest;
/// `[report] figures = "all"` and `--figures all` draw every figure in both
/// formats, with the same results.json.
#[test]
fn a_night_draws_the_summary_and_all_draws_every_figure() {
    let dir = scratch();
    let manifest = crate::shards::campaign(dir.path());
    let text = std::fs::read_to_string(&manifest).unwrap();
    let cut = text
        .find("[[numbered_figures]]")
        .expect("the bundled campaign numbers the paper's figures, last");
    let night = dir.path().join("sim/night.toml");
    std::fs::write(&night, &text[..cut]).unwrap();
    let every = dir.path().join("sim/every.toml");
    std::fs::write(
        &every,
        format!("{}\n[report]\nfigures = \"all\"\n", &text[..cut]),
    )
    .unwrap();
    let run = |manifest: &Path, name: &str, args: &[&str]| {
        let out = dir.path().join(name);
        let mut all = args.to_vec();
        all.push("--quiet");
        let o = servoid_into(dir.path(), "run", manifest, &out, &all);
        assert_eq!(o.code, 0, "{name}: {}", o.stderr);
        out
    };
    let summary = run(&night, "summary", &[]);
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(summary.join("results.json")).unwrap()).unwrap();
    let runs: Vec<(String, String)> = results["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["id"].as_str().unwrap().into(),
                r["role"].as_str().unwrap().into(),
            )
        })
        .collect();
    assert!(
        runs.iter().any(|(_, role)| role == "validation"),
        "{runs:?}"
    );
    let mut expected: Vec<String> = runs
        .iter()
        .flat_map(|(id, role)| {
            let mut f = vec![format!("frf-{id}.png")];
            if role == "validation" {
                f.push(format!("time-{id}.png"));
            }
            f
        })
        .chain(["identification-frf.png", "sensitivity.png"].map(String::from))
        .collect();
    expected.sort();
    assert_eq!(listed(&summary, "figures"), expected);
    let page = std::fs::read_to_string(summary.join("runs/exp1.html")).unwrap();
    assert!(
        page.contains("id=\"more-figures\""),
        "the run's page says how to draw the rest"
    );

    // Every figure, by the manifest's key and by the command line alike.
    let by_key = listed(&run(&every, "by-key", &[]), "figures");
    let all = run(&night, "all", &["--figures", "all"]);
    assert_eq!(listed(&all, "figures"), by_key);
    for f in &expected {
        assert!(by_key.contains(f), "{f} in the summary but not in all");
        assert!(by_key.contains(&f.replace(".png", ".svg")), "{f}'s SVG");
    }
    for id in ["exp1", "spring-k1"] {
        assert!(by_key.contains(&format!("residual-{id}.png")), "{by_key:?}");
    }
    assert!(by_key.contains(&"compensator-exp1.png".to_string()));
    assert!(
        std::fs::read(all.join("results.json")).unwrap()
            == std::fs::read(summary.join("results.json")).unwrap(),
        "results.json does not depend on the figures"
    );
}
