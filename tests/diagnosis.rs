//! Warnings that name the true cause: simulated
//! campaigns of the paper's rig (a no-specimen run and two springs, 60 s
//! quadratic chirps 0.1-35 Hz at 1 kHz, 2 um of LVDT noise, 18-bit
//! converters, default identification settings), each with one thing
//! wrong, put in the logs by the simulator or in the analysis manifest as a
//! lab would write it. Every message of the campaign (run errors first,
//! then the runs' warnings in manifest order, then the campaign's) is
//! sorted into the classes of cause below by what it names; the first
//! message must name the true cause's class, and no message a class that
//! is absent. The confusion table (`cargo test --release diagnosis --
//! --nocapture` prints it) is in docs/accuracy.md.

use servoid::manifest::load;
use servoid::manifest::simulation::load_simulation_str;
use servoid::results::Results;
use servoid::run::analyse;
use servoid::run::simulate::simulate_campaign;

use crate::util::{PaperSweep, scratch};

/// What a message can name as the cause.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Class {
    /// A corrupted sample.
    Sample,
    /// The time base or a unit: the rate, a scale.
    Units,
    /// The FRF settings the manifest names.
    Settings,
    /// Linear dynamics the paper's model lacks: a delay, a mode, a piston.
    Dynamics,
    /// A nonlinearity: friction, a stiffening spring.
    Nonlinear,
    /// What the manifest says of a specimen.
    Specimen,
}

/// The classes a message names as a cause, by the phrases servoid's
/// messages state causes in.
fn classes(message: &str) -> Vec<Class> {
    let m = message.to_lowercase();
    let has = |words: &[&str]| words.iter().any(|w| m.contains(w));
    let table: [(Class, &[&str]); 6] = [
        (Class::Sample, &["isolated spike"]),
        (
            Class::Units,
            &[
                "sampling rate of",
                "static gain",
                "unit mistake",
                "were it milliseconds",
            ],
        ),
        (
            Class::Settings,
            &[
                "identification.frf:",
                "the frf settings the log contradicts",
            ],
        ),
        (
            Class::Dynamics,
            &[
                "support a delay",
                "likely cause: a delay",
                "likely cause: dynamics the model lacks",
                "two modes at once",
                "dynamics the model leaves out",
            ],
        ),
        (
            Class::Nonlinear,
            &[
                "not linear at this amplitude",
                "(friction, a nonlinear specimen",
            ],
        ),
        (
            Class::Specimen,
            &["springs disagree", "the springs' disagreement"],
        ),
    ];
    table
        .iter()
        .filter(|(_, words)| has(words))
        .map(|(c, _)| *c)
        .collect()
}

/// One campaign's case: what is wrong and in which class.
struct Case {
    name: &'static str,
    cause: Option<Class>,
    /// Other causes the case also has (a piston under the friction).
    also: Option<Class>,
    /// Lines for `[rig.unmodelled]`.
    unmodelled: &'static str,
    /// Lines added to `[instrument.displacement]`.
    sensor: &'static str,
    /// The springs as `specimen = ...` (None: linear k1, k2).
    springs: Option<[&'static str; 2]>,
    duration_s: f64,
    at_rest: bool,
    /// The analysis manifest as the lab writes it, from the simulation's.
    edit: fn(String) -> String,
    /// Something done to the logs before the analysis.
    logs: fn(&std::path::Path),
}

fn nothing(s: String) -> String {
    s
}
fn no_logs(_: &std::path::Path) {}

const BASE: Case = Case {
    name: "none",
    cause: None,
    also: None,
    unmodelled: "",
    sensor: "",
    springs: None,
    duration_s: 60.0,
    at_rest: true,
    edit: nothing,
    logs: no_logs,
};

fn simulation(case: &Case, seed: u64) -> String {
    PaperSweep {
        duration_s: case.duration_s,
        at_rest: case.at_rest,
        seed,
        log_format: "csv",
        unmodelled: case.unmodelled,
        sensor: case.sensor,
        springs: case.springs.unwrap_or(PaperSweep::default().springs),
        ..PaperSweep::default()
    }
    .text()
}

/// Every message of a campaign: the runs' errors, then the campaign's
/// warnings (what the rig's identification makes of all the runs), then
/// each run's, in manifest order.
fn messages(results: &Results) -> Vec<String> {
    let mut out: Vec<String> = results
        .runs
        .iter()
        .filter_map(|r| r.error.clone())
        .collect();
    out.extend(results.warnings.iter().cloned());
    for r in &results.runs {
        out.extend(r.warnings.iter().cloned());
    }
    out
}

fn diagnose(case: &Case, seed: u64) -> Vec<String> {
    let dir = scratch();
    let sim = load_simulation_str(&simulation(case, seed), &dir.path().join("sim.toml"))
        .expect("a valid simulation");
    let out = simulate_campaign(&sim, dir.path()).expect("simulates");
    (case.logs)(&dir.path().join("logs"));
    // The lab's manifest names its logs without their SHA-256 (a log a
    // case damages would fail that check first).
    let text: String = std::fs::read_to_string(&out.manifest)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with("sha256 = "))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&out.manifest, (case.edit)(text)).unwrap();
    let campaign = load(&out.manifest).expect("the analysis manifest loads");
    messages(&analyse(&campaign))
}

/// A flipped sample in a spring run's log: the displacement of its sample
/// 30,000 made -3725 mm.
fn spike(logs: &std::path::Path) {
    let path = logs.join("spring-k1.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut fields: Vec<String> = lines[30_001].split(',').map(String::from).collect();
    fields[2] = "-3725.0".into();
    lines[30_001] = fields.join(",");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
}

fn cases() -> Vec<Case> {
    vec![
        BASE,
        Case {
            name: "a spike",
            cause: Some(Class::Sample),
            logs: spike,
            ..BASE
        },
        Case {
            name: "a stated rate the log contradicts",
            cause: Some(Class::Units),
            edit: |s| {
                let t = "[channels.time]\ncolumn = \"time_s\"\nunit = \"s\"";
                assert!(s.contains(t), "{s}");
                s.replace(t, "[channels.time]\nsample_rate_hz = 2000.0")
            },
            ..BASE
        },
        Case {
            name: "a short record with long segments",
            cause: Some(Class::Settings),
            duration_s: 21.0,
            edit: |s| {
                s.replace(
                    "[identification.frf]\nestimator = \"auto\"",
                    "[identification.frf]\nestimator = \"h1\"\nsegment_length = 8192",
                )
            },
            ..BASE
        },
        Case {
            name: "H1 on a sweep not at rest",
            cause: Some(Class::Settings),
            at_rest: false,
            edit: |s| {
                s.replace(
                    "[identification.frf]\nestimator = \"auto\"",
                    "[identification.frf]\nestimator = \"h1\"\nsegment_length = 4096",
                )
            },
            ..BASE
        },
        Case {
            name: "a sensor delay (2 ms)",
            cause: Some(Class::Dynamics),
            sensor: "delay_s = 0.002\n",
            ..BASE
        },
        Case {
            name: "a mode in the command path (110 Hz)",
            cause: Some(Class::Dynamics),
            unmodelled: "command_mode = { natural_frequency_hz = 110.0, damping_ratio = 0.6 }",
            ..BASE
        },
        Case {
            name: "a valve mode in the loop (110 Hz)",
            cause: Some(Class::Dynamics),
            unmodelled: "valve_mode = { natural_frequency_hz = 110.0, damping_ratio = 0.6 }",
            ..BASE
        },
        Case {
            name: "a piston mass (3 kg)",
            cause: Some(Class::Dynamics),
            unmodelled: "piston_mass_kg = 3.0",
            ..BASE
        },
        Case {
            name: "seal friction (20 N) on a 2 kg piston",
            cause: Some(Class::Nonlinear),
            also: Some(Class::Dynamics),
            unmodelled: "piston_mass_kg = 2.0\nactuator_friction = { coulomb_force_n = 20.0, smoothing_velocity_m_per_s = 0.002 }",
            ..BASE
        },
        Case {
            name: "springs stiffening 5 % at 4 mm",
            cause: Some(Class::Nonlinear),
            springs: Some([
                "{ model = \"duffing\", stiffness_n_per_m = 116640.0, cubic_stiffness_n_per_m3 = 3.645e8 }",
                "{ model = \"duffing\", stiffness_n_per_m = 88540.0, cubic_stiffness_n_per_m3 = 2.7669e8 }",
            ]),
            ..BASE
        },
        Case {
            name: "a displacement in mm declared as cm",
            cause: Some(Class::Units),
            edit: |s| {
                let d = "[channels.displacement]\ncolumn = \"displacement_mm\"\nunit = \"mm\"";
                assert!(s.contains(d), "{s}");
                s.replace(d, &d.replace("unit = \"mm\"", "unit = \"cm\""))
            },
            ..BASE
        },
        Case {
            name: "the springs' stiffnesses swapped",
            cause: Some(Class::Specimen),
            edit: |s| {
                s.replace("116640", "KONE")
                    .replace("88540", "116640")
                    .replace("KONE", "88540")
            },
            ..BASE
        },
    ]
}

/// Each case's messages sorted into classes: the first names the true
/// cause's class, none names an absent one; a campaign with nothing wrong
/// has no message.
#[test]
fn warnings_name_the_true_cause() {
    use rayon::prelude::*;
    let cases = cases();
    let seeds = [11u64, 12];
    let outcomes: Vec<(usize, u64, Vec<String>)> = cases
        .par_iter()
        .enumerate()
        .flat_map(|(i, c)| seeds.par_iter().map(move |&s| (i, s, diagnose(c, s))))
        .collect();
    let mut failures = Vec::new();
    eprintln!("| cause | seed | first message's class | every class named | messages |");
    eprintln!("|---|---|---|---|---|");
    for (i, seed, msgs) in &outcomes {
        let case = &cases[*i];
        let first: Vec<Class> = msgs.first().map(|m| classes(m)).unwrap_or_default();
        let mut all: Vec<Class> = msgs.iter().flat_map(|m| classes(m)).collect();
        all.sort();
        all.dedup();
        eprintln!(
            "| {} | {seed} | {first:?} | {all:?} | {} |",
            case.name,
            msgs.len()
        );
        match case.cause {
            None => {
                if !msgs.is_empty() {
                    failures.push(format!("{} ({seed}): {msgs:#?}", case.name));
                }
            }
            Some(cause) => {
                if !first.contains(&cause)
                    || all.iter().any(|c| *c != cause && Some(*c) != case.also)
                {
                    failures.push(format!("{} ({seed}): {msgs:#?}", case.name));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
