//! Whether the stated stds of the rig cover the truth with the settings a
//! lab gets when it writes none: campaigns simulated from a known rig
//! (a no-specimen run and two springs, quadratic chirps 0.1-35 Hz of 4 mm,
//! 2 um of LVDT noise, 18-bit converters) whose analysis manifest leaves
//! `identification.frf` out, as `servoid init` writes it, in groups by
//! record length and by whether the sweep starts and ends at rest. Per
//! group and rig parameter: the scaled errors' (error / stated std) mean
//! and spread, the share within 2 stds and the largest relative error, and
//! the seconds of CPU a campaign took.
//!
//! `cargo bench --bench coverage` (SEEDS per group, 67 by default: 402
//! campaigns over the six groups). `FRF='estimator = "h1"'` analyses with
//! those settings instead; `CASES=20r,60m` picks groups (length in s, `r`
//! at rest, `m` in motion at the ends); `EXCITATION=multisine|noise`.

use std::time::Instant;

use rayon::prelude::*;
use servoid::manifest::load;
use servoid::manifest::simulation::load_simulation_str;
use servoid::results::Results;
use servoid::run::analyse;
use servoid::run::simulate::simulate_campaign;

const TRUTH: [f64; 4] = [267.0, 2.412e9, 7.881e5, 16.118];
const NAMES: [&str; 4] = ["beta1", "a1b0", "a2", "a3"];
/// A group is calibrated when each parameter's scaled errors spread within
/// this band and their mean is within this of 0: over 67 campaigns a
/// spread's own sampling std is about 0.09 and a mean's 0.12.
const SPREAD: (f64, f64) = (0.8, 1.25);
const MEAN: f64 = 0.5;

/// User plus system CPU time of this process (s).
fn cpu_s() -> f64 {
    // SAFETY: getrusage writes into the struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    assert_eq!(rc, 0, "getrusage");
    let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
    t(u.ru_utime) + t(u.ru_stime)
}

#[derive(Clone, Copy)]
struct Group {
    duration_s: f64,
    at_rest: bool,
}

impl Group {
    fn name(&self) -> String {
        format!(
            "{} s, {}",
            self.duration_s,
            if self.at_rest {
                "at rest at the ends"
            } else {
                "in motion at the ends"
            }
        )
    }
    fn sample_rate_hz(&self) -> f64 {
        if self.duration_s >= 150.0 {
            2048.0
        } else {
            1000.0
        }
    }
}

fn excitation(kind: &str, g: &Group) -> String {
    let lead = if g.at_rest { 1.0 } else { 0.0 };
    let body = if g.at_rest {
        g.duration_s - 2.0
    } else {
        g.duration_s
    };
    match kind {
        "chirp" => format!(
            "kind = \"chirp\"\nlaw = \"quadratic\"\nf0_hz = 0.1\nf1_hz = 35.0\nduration_s = {body:?}\namplitude_m = 0.004\nlead_in_s = {lead:?}\nlead_out_s = {lead:?}"
        ),
        "multisine" => format!(
            "kind = \"multisine\"\nf_min_hz = 0.2\nf_max_hz = 35.0\nn_tones = {}\nduration_s = {body:?}\nrms_m = 0.002\nlead_in_s = {lead:?}\nlead_out_s = {lead:?}",
            (body * 10.0) as usize
        ),
        "noise" => format!(
            "kind = \"random_band\"\nf_min_hz = 0.2\nf_max_hz = 40.0\nduration_s = {body:?}\nrms_m = 0.002\nlead_in_s = {lead:?}\nlead_out_s = {lead:?}"
        ),
        other => panic!("EXCITATION={other}: chirp, multisine or noise"),
    }
}

fn manifest(seed: u64, g: &Group, kind: &str, frf: &str) -> String {
    let frf = if frf.is_empty() {
        String::new()
    } else {
        format!("frf = {{ {frf} }}\n")
    };
    format!(
        r#"
schema_version = 1

[simulation]
name = "coverage"
sample_rate_hz = {fs:?}
seed = {seed}
log_format = "parquet"

[rig]
name = "the paper's rig, simulated"

[rig.parameters]
beta1_per_s = {b}
a1b0_n_per_m_s2 = {a}
a2_n_per_m = {a2}
a3_per_s = {a3}

[excitation]
{exc}

[instrument.command]
unit = "mm"
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.displacement]
unit = "mm"
noise_rms = 0.002
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.force]
unit = "N"
noise_rms = 2.0
quantization = {{ bits = 18, full_scale = 5000.0 }}

[identification]
band_hz = [0.5, 30.0]
{frf}
[[runs]]
id = "bare"
role = "no_specimen"
p_gain = 1.0

[[runs]]
id = "k1"
role = "spring"
p_gain = 1.0
specimen = {{ stiffness_n_per_m = 116640.0 }}

[[runs]]
id = "k2"
role = "spring"
p_gain = 1.0
specimen = {{ stiffness_n_per_m = 88540.0 }}
"#,
        fs = g.sample_rate_hz(),
        b = TRUTH[0],
        a = TRUTH[1],
        a2 = TRUTH[2],
        a3 = TRUTH[3],
        exc = excitation(kind, g),
    )
}

fn identify(text: &str) -> Results {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let plan = load_simulation_str(text, &dir.path().join("sim.toml")).expect("a valid simulation");
    let sim = simulate_campaign(&plan, dir.path()).expect("simulates");
    let campaign = load(&sim.manifest).expect("the generated manifest loads");
    analyse(&campaign)
}

struct Outcome {
    /// The runs' fits' reduced chi-square, and the neighbouring residuals'
    /// correlation.
    chi2: Vec<(f64, f64)>,
    z: [f64; 4],
    rel: [f64; 4],
    joint_used: bool,
    warnings: Vec<String>,
}

fn outcome(results: &Results) -> Option<Outcome> {
    let r = results.rig.as_ref()?;
    let est = [&r.beta1, &r.a1b0, &r.a2, &r.a3];
    let mut warnings: Vec<String> = results.warnings.iter().map(|w| w.detail.clone()).collect();
    for run in &results.runs {
        warnings.extend(run.warnings.iter().map(|w| w.detail.clone()));
        if let Some(e) = &run.error {
            warnings.push(format!("run {} failed: {e}", run.id));
        }
    }
    let chi2 = results
        .runs
        .iter()
        .filter_map(|r| r.fit.as_ref())
        .map(|f| {
            (
                f.reduced_chi2,
                f.adequacy
                    .as_ref()
                    .and_then(|a| a.correlation.as_ref())
                    .map_or(f64::NAN, |c| c.r),
            )
        })
        .collect();
    Some(Outcome {
        chi2,
        z: std::array::from_fn(|k| (est[k].value - TRUTH[k]) / est[k].std.unwrap_or(f64::NAN)),
        rel: std::array::from_fn(|k| est[k].value / TRUTH[k] - 1.0),
        joint_used: matches!(r.source, servoid::results::RigSource::Joint),
        warnings,
    })
}

fn main() {
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    let seeds: u64 = std::env::var("SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(67);
    let frf = std::env::var("FRF").unwrap_or_default();
    let kind = std::env::var("EXCITATION").unwrap_or_else(|_| "chirp".into());
    let groups: Vec<Group> = match std::env::var("CASES") {
        Ok(s) => s
            .split(',')
            .map(|g| Group {
                duration_s: g[..g.len() - 1].parse().expect("CASES: 20r,60m,..."),
                at_rest: g.ends_with('r'),
            })
            .collect(),
        Err(_) => [20.0, 60.0, 170.0]
            .into_iter()
            .flat_map(|d| {
                [true, false].map(|at_rest| Group {
                    duration_s: d,
                    at_rest,
                })
            })
            .collect(),
    };
    println!(
        "coverage: {seeds} campaigns per group, {kind}, identification.frf {}",
        if frf.is_empty() {
            "left out (the defaults)".to_string()
        } else {
            format!("= {{ {frf} }}")
        }
    );
    let (mut campaigns, mut all_calibrated) = (0, true);
    for g in &groups {
        let (wall, cpu) = (Instant::now(), cpu_s());
        let outcomes: Vec<Option<Outcome>> = (0..seeds)
            .into_par_iter()
            .map(|s| {
                let results = identify(&manifest(9000 + s, g, &kind, &frf));
                if let Ok(dir) = std::env::var("DUMP") {
                    let path = format!(
                        "{dir}/{}{}-{s}.json",
                        g.duration_s,
                        if g.at_rest { "r" } else { "m" }
                    );
                    std::fs::write(path, serde_json::to_string_pretty(&results).unwrap()).unwrap();
                }
                outcome(&results)
            })
            .collect();
        let cpu = cpu_s() - cpu;
        let ok: Vec<&Outcome> = outcomes.iter().flatten().collect();
        let n = ok.len() as f64;
        println!(
            "\n{}: {} of {seeds} campaigns gave a rig ({} the joint one); {:.2} s of CPU a campaign ({:.1} s wall in all)",
            g.name(),
            ok.len(),
            ok.iter().filter(|o| o.joint_used).count(),
            cpu / seeds as f64,
            wall.elapsed().as_secs_f64()
        );
        for (k, name) in NAMES.iter().enumerate() {
            let mean = ok.iter().map(|o| o.z[k]).sum::<f64>() / n;
            let sd = (ok.iter().map(|o| (o.z[k] - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let within = ok.iter().filter(|o| o.z[k].abs() <= 2.0).count() as f64 / n;
            let worst = ok.iter().map(|o| o.rel[k].abs()).fold(0.0, f64::max);
            let calibrated = (SPREAD.0..=SPREAD.1).contains(&sd) && mean.abs() < MEAN;
            all_calibrated &= calibrated;
            println!(
                "  {name:6} scaled error mean {mean:+.3}, spread {sd:.3}{}; {:.1} % within 2 stds; largest error {:.4} %",
                if calibrated { "" } else { " (OUTSIDE)" },
                100.0 * within,
                100.0 * worst
            );
        }
        let fits: Vec<(f64, f64)> = ok.iter().flat_map(|o| o.chi2.iter().copied()).collect();
        let m = fits.len().max(1) as f64;
        println!(
            "  the runs' own fits: reduced chi-square {:.3} on average, neighbouring residuals' correlation {:+.3}",
            fits.iter().map(|f| f.0).sum::<f64>() / m,
            fits.iter().map(|f| f.1).sum::<f64>() / m
        );
        let mut tally: Vec<(String, usize)> = Vec::new();
        for o in &ok {
            for w in &o.warnings {
                let key: String = w.chars().take(90).collect();
                match tally.iter_mut().find(|(k, _)| *k == key) {
                    Some((_, c)) => *c += 1,
                    None => tally.push((key, 1)),
                }
            }
        }
        tally.sort_by_key(|t| std::cmp::Reverse(t.1));
        for (w, c) in tally.iter().take(6) {
            println!("  warning x{c}: {w}...");
        }
        campaigns += ok.len();
        all_calibrated &= ok.len() as u64 == seeds;
    }
    println!(
        "\n{campaigns} campaigns: {}",
        if all_calibrated {
            format!(
                "every group's scaled errors spread {}-{} with |mean| < {MEAN}",
                SPREAD.0, SPREAD.1
            )
        } else {
            "a group is OUTSIDE the calibration band, or a campaign gave no rig".into()
        }
    );
}
