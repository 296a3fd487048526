//! The HTML report in a real browser: headless Chromium (Debian's `chromium`
//! package) opens `report.html`, and the test fails on any console error,
//! uncaught exception, error log entry or broken image. A full-page
//! `screenshot.png` is saved beside the report. Where Chromium is not
//! installed these tests say SKIPPED with the install command, unless
//! `SERVOID_REQUIRE_CHROMIUM` is set (`.ci/run` sets it and installs it).
//!
//! Run with `cargo test --test integration browser`.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::cdp::{Browser, CdpError, VIEWPORT_WIDTH_PX};
use crate::util::{paper_tf_runs, root, scratch, servoid, skipped, write};

/// Set (to anything but `0`) where Chromium must be there: CI sets it, so a
/// missing browser fails the run instead of skipping these tests.
const REQUIRE_CHROMIUM: &str = "SERVOID_REQUIRE_CHROMIUM";

/// Start Chromium. Where it is not installed the test is SKIPPED with the
/// install command, unless `SERVOID_REQUIRE_CHROMIUM` asks for it; any
/// other failure to start it fails the test.
fn browser(test: &str) -> Option<Browser> {
    match Browser::launch() {
        Ok(b) => Some(b),
        Err(CdpError::NotInstalled)
            if std::env::var_os(REQUIRE_CHROMIUM).is_none_or(|v| v == "0") =>
        {
            skipped(&format!(
                "{test}: needs Debian's chromium (apt-get install -y chromium); set {REQUIRE_CHROMIUM}=1 to make its absence a failure"
            ));
            None
        }
        Err(e) => panic!("{e}"),
    }
}

/// Run `servoid run manifest --out dir/out`, expecting exit `code`; returns
/// the output folder.
fn run_campaign(dir: &Path, manifest: &Path, code: i32) -> PathBuf {
    let out = dir.join("out");
    let o = servoid(
        dir,
        &[
            "run",
            manifest.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(
        o.code, code,
        "exit code; stdout:\n{}\nstderr:\n{}",
        o.stdout, o.stderr
    );
    assert!(out.join("report.html").is_file(), "report.html written");
    out
}

/// Open the report, assert that nothing on it is broken, save the
/// screenshot and check it is a PNG of the page's size.
fn open_clean(b: &mut Browser, out: &Path) {
    open_clean_page(b, &out.join("report.html"));
}

/// Open `page`, assert that nothing on it is broken, save the screenshot
/// beside it and check it is a PNG of the page's size.
fn open_clean_page(b: &mut Browser, page: &Path) {
    let out = page.parent().unwrap();
    b.open(page).unwrap();
    let errors = b.errors().unwrap();
    assert!(errors.is_empty(), "console errors:\n{}", errors.join("\n"));
    let images = b.images().unwrap();
    assert!(
        images.broken.is_empty(),
        "{} of {} images are broken: {:?}",
        images.broken.len(),
        images.total,
        images.broken
    );
    let shot = out.join("screenshot.png");
    let (width, height) = b.screenshot(&shot).unwrap();
    let png = std::fs::read(&shot).expect("screenshot.png saved in the report folder");
    assert_eq!(png_size(&png), (width, height), "the PNG is the whole page");
    assert_eq!(width, VIEWPORT_WIDTH_PX);
    // A blank page compresses to a few hundred bytes; one with tables and
    // text does not.
    assert!(png.len() > 20_000, "screenshot of {} bytes", png.len());
}

/// Width and height from a PNG's IHDR chunk, after checking the signature
/// (PNG specification, sections 5.2 and 11.2.2).
fn png_size(png: &[u8]) -> (u32, u32) {
    assert!(png.len() > 24, "a PNG of {} bytes", png.len());
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&png[12..16], b"IHDR", "the first chunk is IHDR");
    let be = |b: &[u8]| u32::from_be_bytes(b.try_into().unwrap());
    (be(&png[16..20]), be(&png[20..24]))
}

/// Text of a JavaScript expression's string value.
fn text(v: Value) -> String {
    v.as_str()
        .unwrap_or_else(|| panic!("expected a string, got {v}"))
        .to_string()
}

#[test]
fn paper_report_renders_without_errors() {
    let dir = scratch();
    let out = run_campaign(
        dir.path(),
        &root().join("experiments/maghareh2018/paper.toml"),
        0,
    );
    let Some(mut b) = browser("paper_report_renders_without_errors") else {
        return;
    };
    open_clean(&mut b, &out);

    assert_eq!(
        text(b.evaluate("document.title").unwrap()),
        "servoid: maghareh2018-paper"
    );
    // Table 3's columns are the paper's four experiments (its Table 2).
    let table3_head = b
        .evaluate(
            "Array.from(document.querySelector('#table3 + p + table tr').cells)\
             .map(c => c.textContent.trim())",
        )
        .unwrap();
    assert_eq!(
        table3_head,
        serde_json::json!(["Parameter", "exp1", "exp2", "exp3", "exp4"])
    );
    // The comparisons list every reference of the manifest; the flagged rows
    // are Table 3's C1-C3 for each of the four experiments (3 x 4 = 12):
    // they do not follow from the paper's own equations with m = 3.8 kg
    // (docs/model.md), while every other published number agrees.
    let flagged = b
        .evaluate(
            "Array.from(document.querySelectorAll('#comparisons + table tr.flag'))\
             .map(r => r.cells[0].textContent.trim())",
        )
        .unwrap();
    let mut flagged: Vec<String> = flagged
        .as_array()
        .expect("a list")
        .iter()
        .map(|v| text(v.clone()))
        .collect();
    flagged.sort();
    let mut want: Vec<String> = (1..=4)
        .flat_map(|e| (1..=3).map(move |c| format!("ccf.exp{e}.C{c}")))
        .collect();
    want.sort();
    assert_eq!(flagged, want);
    let manifest =
        std::fs::read_to_string(root().join("experiments/maghareh2018/paper.toml")).unwrap();
    let references = manifest.matches("[[references]]").count();
    let rows = b
        .evaluate("document.querySelectorAll('#comparisons + table tr').length")
        .unwrap();
    assert_eq!(
        rows.as_u64(),
        Some(references as u64 + 1),
        "a header row and one row per reference"
    );
    b.close().unwrap();
}

/// `servoid design`'s page (here from a campaign manifest's nominal rig)
/// in Chromium: nothing broken, its figure drawn at its size, a row per
/// designed run and per parameter, each command linked to a file there.
#[test]
fn a_design_page_renders_with_its_figure_and_tables() {
    let dir = scratch();
    let manifest = write(
        dir.path(),
        "nominal.toml",
        &std::fs::read_to_string(root().join("tests/fixtures/nominal-campaign.toml")).unwrap(),
    );
    let out = dir.path().join("design");
    let o = servoid(
        dir.path(),
        &[
            "design",
            manifest.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--rate-hz",
            "1000",
            "--noise-mm",
            "0.002",
        ],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let Some(mut b) = browser("a_design_page_renders_with_its_figure_and_tables") else {
        return;
    };
    open_clean_page(&mut b, &out.join("design.html"));
    assert_eq!(
        text(b.evaluate("document.title").unwrap()),
        "servoid design: first-night"
    );
    let figure = b
        .evaluate("[document.querySelectorAll('figure img').length, document.querySelector('#lines img').naturalWidth]")
        .unwrap();
    assert_eq!(figure, serde_json::json!([1, 1200]));
    let rows = b
        .evaluate("[document.querySelectorAll('#design-runs tr').length, document.querySelectorAll('#design-precision tr').length]")
        .unwrap();
    assert_eq!(
        rows,
        serde_json::json!([3, 5]),
        "a header and a row per run, per parameter"
    );
    let links = b
        .evaluate("Array.from(document.querySelectorAll('#design-runs a')).map(a => a.getAttribute('href'))")
        .unwrap();
    for link in links.as_array().unwrap() {
        let file = out.join(link.as_str().unwrap());
        assert!(file.is_file(), "{}", file.display());
    }
    b.close().unwrap();
}

#[test]
fn the_harness_catches_console_errors_and_broken_images() {
    let dir = scratch();
    // A valid 1 x 1 PNG beside a broken one: the check must tell them apart.
    let page = write(
        dir.path(),
        "bad.html",
        r#"<!DOCTYPE html><html><head><meta charset="utf-8"><title>bad</title></head><body>
<img alt="fine" src="data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNkYPhfDwAChwGA60e6kgAAAABJRU5ErkJggg==">
<img alt="broken on purpose" src="data:image/png;base64,AAAA">
<script>console.log("not an error"); console.error("deliberate failure", 42);</script>
</body></html>"#,
    );
    // The other two channels: an uncaught exception, and a missing file
    // (an error entry of the browser's log) that is also a broken image.
    let page2 = write(
        dir.path(),
        "bad2.html",
        r#"<!DOCTYPE html><html><head><meta charset="utf-8"><title>bad2</title></head><body>
<img alt="missing" src="no-such-figure.png">
<script>throw new Error("thrown on purpose");</script>
</body></html>"#,
    );
    let Some(mut b) = browser("the_harness_catches_console_errors_and_broken_images") else {
        return;
    };

    b.open(&page).unwrap();
    let errors = b.errors().unwrap();
    assert_eq!(errors.len(), 1, "{errors:#?}");
    assert!(
        errors[0].starts_with("console.error: deliberate failure 42 (file://"),
        "{errors:?}"
    );
    assert!(errors[0].ends_with("bad.html:4)"), "{errors:?}");
    let images = b.images().unwrap();
    assert_eq!(images.total, 2);
    assert_eq!(
        images.broken,
        ["broken on purpose: data:image/png;base64,AAAA"]
    );

    b.open(&page2).unwrap();
    let errors = b.errors().unwrap();
    assert_eq!(errors.len(), 2, "{errors:#?}");
    assert!(
        errors
            .iter()
            .any(|e| e.starts_with("uncaught exception: Error: thrown on purpose")),
        "{errors:#?}"
    );
    assert!(
        errors
            .iter()
            .any(|e| e.starts_with("log (network): ") && e.contains("no-such-figure.png")),
        "{errors:#?}"
    );
    assert_eq!(b.images().unwrap().broken, ["missing: no-such-figure.png"]);
    b.close().unwrap();
}

/// A campaign whose spring model gives a non-physical R2 (its static gain
/// d0/n0 = 2600/2703 < 1), so identification fails and the validation run
/// cannot be predicted; the same case as `manifest_errors`'s
/// `a_failed_run_exits_1_and_the_others_complete`.
fn failing() -> String {
    concat!(
        r#"schema_version = 1

[campaign]
name = "failing"

[rig]
name = "test rig"

"#,
        paper_tf_runs!(),
        r#"
[[runs]]
id = "exp1"
role = "validation"
p_gain = 1.0
specimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }
"#
    )
    .replace("den = [1.0, 263.4, 3337.0]", "den = [1.0, 263.4, 2600.0]")
}

#[test]
fn a_report_with_a_failed_run_renders_and_shows_the_error() {
    let dir = scratch();
    let manifest = write(dir.path(), "campaign.toml", &failing());
    let out = run_campaign(dir.path(), &manifest, 1);
    let results: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let run_error = text(results["runs"][2]["error"].clone());
    assert!(run_error.contains("rig parameters are unavailable"));

    let Some(mut b) = browser("a_report_with_a_failed_run_renders_and_shows_the_error") else {
        return;
    };
    open_clean(&mut b, &out);
    assert_eq!(
        text(b.evaluate("document.title").unwrap()),
        "servoid: failing"
    );
    // The run's row shows its status and results.json's error text.
    assert_eq!(
        text(
            b.evaluate("document.querySelector('#run-exp1 .status').textContent")
                .unwrap()
        ),
        "failed"
    );
    assert_eq!(
        text(
            b.evaluate("document.querySelector('#run-exp1 .error').textContent")
                .unwrap()
        ),
        run_error
    );
    let rig_error = text(
        b.evaluate("document.querySelector('#rig-error').textContent")
            .unwrap(),
    );
    assert!(rig_error.contains("k1"), "{rig_error}");
    b.close().unwrap();
}

/// The pages of the bundled default (the paper's campaign, simulated): the
/// campaign's page small (under 3 MB; figures are files beside it, not
/// inlined), one page per run linked from it with that run's figures, and
/// in Chromium every page complete, with every image decoded. The load time
/// the browser measures (navigation start to the end of the load event) is
/// printed, not asserted: tests never time.
#[test]
fn the_bundled_default_pages_are_light_and_complete() {
    let dir = scratch();
    let out = dir.path().join("out");
    let o = crate::util::servoid_into(
        dir.path(),
        "simulate",
        &root().join("experiments/maghareh2018/simulation.toml"),
        &out,
        &["--run", "--quiet"],
    );
    assert_eq!(o.code, 0, "stderr:\n{}", o.stderr);
    let page = out.join("report.html");
    let bytes = std::fs::metadata(&page).unwrap().len();
    assert!(
        bytes < 3_000_000,
        "report.html is {bytes} bytes; the page must stay under 3 MB"
    );
    // minijinja escapes `/` in attributes as `&#x2f;`; the browser reads both
    // alike.
    let read = |p: &Path| std::fs::read_to_string(p).unwrap().replace("&#x2f;", "/");
    let html = read(&page);
    // The Monte Carlo's figures and table (on in the bundled default).
    for id in ["sensitivity-monte-carlo", "sensitivity-bias"] {
        assert!(html.contains(&format!("figures/{id}.png")), "{id}");
    }
    assert!(html.contains("id=\"monte-carlo-table\""));
    let svgs = figure_files(&out, "svg");
    let pngs = figure_files(&out, "png");
    assert!(svgs.len() >= 20, "{} SVG figures", svgs.len());
    assert_eq!(svgs.len(), pngs.len());
    let runs = [
        "no-specimen",
        "spring-k1",
        "spring-k2",
        "exp1",
        "exp2",
        "exp3",
        "exp4",
    ];
    // Every figure is linked from exactly one page, as PNG and as SVG.
    let mut pages = vec![html.clone()];
    for id in runs {
        assert!(
            html.contains(&format!("href=\"runs/{id}.html\"")),
            "the campaign page links run {id}'s page"
        );
        pages.push(read(&out.join(format!("runs/{id}.html"))));
    }
    for f in svgs.iter().chain(&pngs) {
        let linked = pages
            .iter()
            .filter(|p| p.contains(&format!("figures/{f}\"")))
            .count();
        assert_eq!(linked, 1, "figures/{f} is linked from one page");
    }
    // The paper's figures by number: every one of its 22 is named in the
    // manifest, each drawn one a byte-for-byte copy of the figure it names
    // (fig-08 of frf-no-specimen, fig-16a of force-exp1), shown on the
    // campaign page; each other listed there with why it is not drawn.
    let manifest: toml::Table = toml::from_str(
        &std::fs::read_to_string(root().join("experiments/maghareh2018/simulation.toml")).unwrap(),
    )
    .unwrap();
    let mut numbers = Vec::new();
    for n in manifest["numbered_figures"].as_array().unwrap() {
        let number = n["number"].as_str().unwrap();
        let digits: String = number.chars().filter(char::is_ascii_digit).collect();
        numbers.push(digits.parse::<u32>().unwrap());
        let stem = format!("fig-{digits:0>2}{}", &number[digits.len()..]);
        match n.get("figure").and_then(|f| f.as_str()) {
            Some(figure) => {
                for ext in ["png", "svg"] {
                    let copy = std::fs::read(out.join(format!("figures/{stem}.{ext}"))).unwrap();
                    let source =
                        std::fs::read(out.join(format!("figures/{figure}.{ext}"))).unwrap();
                    assert!(copy == source, "{stem}.{ext} is {figure}.{ext}");
                }
                assert!(
                    html.contains(&format!("<figure id=\"{stem}\">")),
                    "{stem} shown"
                );
            }
            None => assert!(
                html.contains(&format!("<li><b>Fig. {number}</b>")),
                "Fig. {number} listed as not drawn"
            ),
        }
    }
    numbers.dedup();
    assert_eq!(numbers, (1..=22).collect::<Vec<u32>>());

    let Some(mut b) = browser("the_bundled_default_pages_are_light_and_complete") else {
        return;
    };
    open_clean(&mut b, &out);
    let load_ms = load_time_ms(&mut b);
    for id in ["figures", "runs", "comparisons", "provenance"] {
        let found = b
            .evaluate(&format!("document.getElementById('{id}') !== null"))
            .unwrap();
        assert_eq!(found, serde_json::json!(true), "section #{id}");
    }
    let mut figures = b
        .evaluate("document.querySelectorAll('figure img').length")
        .unwrap()
        .as_u64()
        .unwrap();
    for id in runs {
        let run_page = out.join(format!("runs/{id}.html"));
        b.open(&run_page).unwrap();
        let errors = b.errors().unwrap();
        assert!(errors.is_empty(), "{id}: {}", errors.join("\n"));
        let images = b.images().unwrap();
        assert!(images.broken.is_empty(), "{id}: {:?}", images.broken);
        figures += images.total as u64;
    }
    assert_eq!(figures, svgs.len() as u64, "every figure is shown once");
    crate::util::note(&format!(
        "the bundled default's report.html ({bytes} bytes) loaded in Chromium in {load_ms:.0} ms; {} figures over {} pages",
        svgs.len(),
        runs.len() + 1
    ));
}

/// The document's load time as the browser measured it (ms), after checking
/// the document is complete.
fn load_time_ms(b: &mut Browser) -> f64 {
    let state = b
        .evaluate(
            "({ ready: document.readyState, \
             load_ms: performance.getEntriesByType('navigation')[0].loadEventEnd })",
        )
        .unwrap();
    assert_eq!(state["ready"], "complete");
    state["load_ms"].as_f64().expect("a load time")
}

/// File names under `out/figures` with extension `ext`, sorted.
fn figure_files(out: &Path, ext: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(out.join("figures"))
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(&format!(".{ext}")))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// A campaign of 500 runs: the rig from the paper's published transfer
/// functions and 498 validation runs, predictions without logs (the page is
/// what is measured, not the analysis). The campaign's page lists every run
/// and opens complete in Chromium; the load time is printed (the issue's
/// target is under 2 s; tests never time). Sorting and filtering work.
#[test]
fn a_500_run_campaign_page_is_complete_sortable_and_filterable() {
    let dir = scratch();
    let mut text = String::from(concat!(
        "schema_version = 1\n[campaign]\nname = \"night-500\"\n[rig]\nname = \"frame B\"\n\n",
        crate::util::paper_tf_runs!()
    ));
    for k in 0..498 {
        text.push_str(&format!(
            "\n[[runs]]\nid = \"v{k:03}\"\nrole = \"validation\"\np_gain = 1.0\nspecimen = {{ mass_kg = {m}, damping_ns_per_m = 5.0, stiffness_n_per_m = {s} }}\n",
            m = 2.0 + (k % 7) as f64,
            s = 60_000.0 + 250.0 * k as f64
        ));
    }
    let manifest = write(dir.path(), "night.toml", &text);
    let out = run_campaign(dir.path(), &manifest, 0);
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(page.matches("<tr id=\"run-").count(), 500);
    assert_eq!(std::fs::read_dir(out.join("runs")).unwrap().count(), 500);

    let Some(mut b) = browser("a_500_run_campaign_page_is_complete_sortable_and_filterable") else {
        return;
    };
    open_clean(&mut b, &out);
    let load_ms = load_time_ms(&mut b);
    let rows = |b: &mut Browser| {
        b.evaluate(
            "Array.from(document.querySelectorAll('#run-table tbody tr'))\
             .filter(r => !r.hidden).map(r => r.id)",
        )
        .unwrap()
    };
    let all = rows(&mut b);
    assert_eq!(all.as_array().unwrap().len(), 500);
    assert_eq!(all[0], "run-ns");
    // The run column sorts by id: v497 last ascending, first descending.
    let head = "document.querySelector('#run-table thead th')";
    b.evaluate(&format!("{head}.click()")).unwrap();
    let asc = rows(&mut b);
    assert_eq!(asc[499], "run-v497", "{asc:?}");
    b.evaluate(&format!("{head}.click()")).unwrap();
    assert_eq!(rows(&mut b)[0], "run-v497");
    // Filtering on text keeps the matching runs.
    b.evaluate(
        "const f = document.getElementById('run-filter'); f.value = 'v12'; \
         f.dispatchEvent(new Event('input'))",
    )
    .unwrap();
    let shown = rows(&mut b);
    let ids: Vec<&str> = shown
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(ids.len(), 10, "{ids:?}");
    assert!(ids.iter().all(|id| id.starts_with("run-v12")), "{ids:?}");
    crate::util::note(&format!(
        "a 500-run campaign's report.html ({} bytes) loaded in Chromium in {load_ms:.0} ms",
        page.len()
    ));
}

/// A night whose runs share a warning (each run's command limited at 3 mm
/// in the controller): in Chromium each run's status cell in the campaign
/// page's runs table takes a line or two (its status and a link to its
/// warnings), and below the table the warning is listed once with a link
/// to each run's warnings.
#[test]
fn a_warning_the_runs_share_is_listed_once_and_each_run_keeps_one_line() {
    let dir = scratch();
    let sim = crate::util::PaperSweep {
        excitation: Some(
            "kind = \"chirp\"\nlaw = \"quadratic\"\nf0_hz = 0.1\nf1_hz = 35.0\nduration_s = 58.0\namplitude_m = 0.004\nlimit_m = 0.003\nlead_in_s = 1.0\nlead_out_s = 1.0",
        ),
        validation: true,
        log_format: "csv",
        ..Default::default()
    };
    let manifest = write(dir.path(), "night.toml", &sim.text());
    let out = dir.path().join("out");
    let o = crate::util::servoid_into(
        dir.path(),
        "simulate",
        &manifest,
        &out,
        &["--run", "--quiet", "--figures", "none"],
    );
    assert_eq!(o.code, 0, "stderr:\n{}", o.stderr);
    let Some(mut b) =
        browser("a_warning_the_runs_share_is_listed_once_and_each_run_keeps_one_line")
    else {
        return;
    };
    b.open(&out.join("report.html")).unwrap();
    let errors = b.errors().unwrap();
    assert!(errors.is_empty(), "console errors:\n{}", errors.join("\n"));
    // Each run's status cell: the height its content takes, in lines of
    // its text (a warning's paragraphs in it took some 1,000 px a run).
    let lines = b
        .evaluate(
            "Array.from(document.querySelectorAll('#run-table tbody tr')).map(r => {\
               const td = r.children[4]; const range = document.createRange();\
               range.selectNodeContents(td);\
               const line = parseFloat(getComputedStyle(td).lineHeight) || 1.2 * parseFloat(getComputedStyle(td).fontSize);\
               return range.getBoundingClientRect().height / line; })",
        )
        .unwrap();
    let lines: Vec<f64> = lines
        .as_array()
        .unwrap()
        .iter()
        .map(|h| h.as_f64().unwrap())
        .collect();
    assert_eq!(lines.len(), 4, "{lines:?}");
    assert!(
        lines.iter().all(|&l| l > 0.5 && l < 2.6),
        "status cells of {lines:?} lines"
    );
    let shared = b
        .evaluate(
            "Array.from(document.querySelector('#run-warnings ~ ul.warn').querySelectorAll('li'))\
             .map(li => [li.textContent, li.querySelectorAll('a').length])",
        )
        .unwrap();
    let limited: Vec<&Value> = shared
        .as_array()
        .unwrap()
        .iter()
        .filter(|li| text(li[0].clone()).contains("a limit set in the controller"))
        .collect();
    assert_eq!(limited.len(), 1, "listed once: {shared}");
    assert_eq!(limited[0][1], 4, "with each run's link: {shared}");
}
