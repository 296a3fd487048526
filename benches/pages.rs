//! The pages of a large campaign: the campaign's page (status table, rig,
//! Table 3, ...) and every run's own page, rendered in memory (no files
//! written) for 1,000 to 8,000 runs. Rendering must grow linearly with the
//! number of runs: the time per run (criterion's throughput, runs/s) is
//! the same at 4,000 and 8,000 runs. (The single-page template this
//! replaced grew quadratically: 2.3 s at 4,000 runs, 9 s at 8,000.)
//! Measured on two cores: 26 ms at 1,000 runs, 53 ms at 2,000, 110 ms at
//! 4,000 and 226 ms at 8,000 (38,000 to 35,000 runs/s; 8,000 over 4,000:
//! 2.05).
//!
//! The results are the paper's campaign (`experiments/maghareh2018/
//! paper.toml`: the rig from its published transfer functions, Exp1-Exp4
//! predicted), its runs repeated under new ids, with their canonical forms.
//!
//! `cargo bench --bench pages`

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use servoid::report::html::Pages;
use servoid::results::Results;

/// The paper's results with `n` runs: its runs repeated in turn, each copy
/// under its own id (and its canonical form with it).
fn campaign(n: usize) -> Results {
    let manifest = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/experiments/maghareh2018/paper.toml"
    );
    let campaign = servoid::manifest::load(std::path::Path::new(manifest)).expect("paper.toml");
    let paper = servoid::run::analyse(&campaign);
    let mut results = paper.clone();
    results.runs.clear();
    results.ccf.clear();
    for k in 0..n {
        let mut run = paper.runs[k % paper.runs.len()].clone();
        let id = format!("{}-{k:05}", run.id);
        if let Some(ccf) = paper.ccf.iter().find(|c| c.run == run.id) {
            let mut ccf = ccf.clone();
            ccf.run = id.clone();
            results.ccf.push(ccf);
        }
        run.id = id;
        results.runs.push(run);
    }
    results
}

/// Every page of `results`; their total length (so nothing is optimised
/// away).
fn render(results: &Results) -> usize {
    let pages = Pages::new(results, servoid::report::FigureFormats::None).expect("templates");
    let mut page = Vec::new();
    pages.campaign(&[], &mut page).expect("campaign page");
    let mut bytes = page.len();
    for run in &results.runs {
        bytes += pages.run(run, &[]).expect("run page").len();
    }
    bytes
}

fn bench_pages(c: &mut Criterion) {
    let mut group = c.benchmark_group("pages");
    group.sample_size(10);
    for n in [1_000, 2_000, 4_000, 8_000] {
        let results = campaign(n);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::from_parameter(n), &results, |b, r| {
            b.iter(|| black_box(render(black_box(r))))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_pages);
criterion_main!(benches);
