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

use servoid::results::Results;

use crate::util::{PaperSweep, analysed_simulation, rewrite_column};

/// What a message can name as the cause.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Class {
    /// A corrupted sample or stretch of samples.
    Sample,
    /// A channel that does not read its signal: stuck, dropped, frozen,
    /// inverted, clipped, read through a nonlinearity.
    Channel,
    /// The time base or a unit: the rate, a scale.
    Units,
    /// A time column that holds two recordings or samples out of order.
    TimeBase,
    /// A converter too coarse for the signal.
    Quantisation,
    /// The FRF settings the manifest names.
    Settings,
    /// Linear dynamics the paper's model lacks: a delay, a mode, a piston.
    Dynamics,
    /// A nonlinearity: friction, a stiffening spring, a gain that depends
    /// on the load.
    Nonlinear,
    /// What the manifest says of a specimen.
    Specimen,
}

/// The classes a message names as a cause, by the phrases servoid's
/// messages state causes in.
fn classes(message: &str) -> Vec<Class> {
    let m = message.to_lowercase();
    let has = |words: &[&str]| words.iter().any(|w| m.contains(w));
    let table: [(Class, &[&str]); 9] = [
        (Class::Sample, &["isolated spike", "corrupt stretch"]),
        (
            Class::Channel,
            &[
                "stuck sensor",
                "a dropout of the sensor",
                "the daq stalled",
                "wired backwards",
                "is clipped",
                "a nonlinearity the loop does not see",
            ],
        ),
        (
            Class::Units,
            &[
                "sampling rate of",
                "static gain",
                "unit mistake",
                "were it milliseconds",
                "wrong unit or scale",
            ],
        ),
        (
            Class::TimeBase,
            &["two recordings in one file", "two stamps out of order"],
        ),
        (Class::Quantisation, &["coarse quantisation"]),
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
                "a gain that depends on the load",
            ],
        ),
        (
            Class::Specimen,
            &[
                "stiffness typed wrong",
                "the spring's stiffness the manifest states",
                "swapped in the manifest",
            ],
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
    /// The converters' bits.
    bits: u32,
    /// Lines of the simulated `[rig]` table.
    rig: &'static str,
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
    bits: 18,
    rig: "",
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
        bits: case.bits,
        rig: case.rig,
        ..PaperSweep::default()
    }
    .text()
}

/// Every message of a campaign: the runs' errors, then the campaign's
/// warnings (what the rig's identification makes of all the runs), then
/// each run's, in manifest order; each warning's detail, its headline
/// checked for length (a lab reads it at a glance).
fn messages(results: &Results) -> Vec<String> {
    for w in results
        .warnings
        .iter()
        .chain(results.runs.iter().flat_map(|r| &r.warnings))
    {
        assert!(
            w.headline.chars().count() <= servoid::warning::HEADLINE_MAX,
            "a headline over {} characters: {}",
            servoid::warning::HEADLINE_MAX,
            w.headline
        );
    }
    let mut out: Vec<String> = results
        .runs
        .iter()
        .filter_map(|r| r.error.clone())
        .collect();
    out.extend(results.warnings.iter().map(|w| w.detail.clone()));
    for r in &results.runs {
        out.extend(r.warnings.iter().map(|w| w.detail.clone()));
    }
    out
}

fn diagnose(case: &Case, seed: u64) -> Vec<String> {
    messages(&analysed_simulation(
        &simulation(case, seed),
        case.logs,
        case.edit,
    ))
}

/// Column `col` of the log of run `run` rewritten by `f(sample, value)`.
fn rewrite(logs: &std::path::Path, run: &str, col: usize, f: impl Fn(usize, &str) -> String) {
    rewrite_column(&logs.join(format!("{run}.csv")), col, f);
}

/// Every log's column `col` rewritten.
fn rewrite_all(logs: &std::path::Path, col: usize, f: impl Fn(usize, &str) -> String + Copy) {
    for run in ["no-specimen", "spring-k1", "spring-k2"] {
        rewrite(logs, run, col, f);
    }
}

fn negated(v: &str) -> String {
    format!("{}", -v.parse::<f64>().unwrap())
}

/// Three adjacent samples of the no-specimen displacement 1.7 mm off.
fn corrupt_stretch(logs: &std::path::Path) {
    rewrite(logs, "no-specimen", 2, |k, v| match k {
        20_000..20_003 => format!("{}", v.parse::<f64>().unwrap() + 1.7),
        _ => v.to_string(),
    });
}

/// The no-specimen displacement stuck for 2 s.
fn stuck(logs: &std::path::Path) {
    let path = logs.join("no-specimen.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let held = text
        .lines()
        .nth(20_001)
        .unwrap()
        .split(',')
        .nth(2)
        .unwrap()
        .to_string();
    rewrite(logs, "no-specimen", 2, |k, v| match k {
        20_000..22_000 => held.clone(),
        _ => v.to_string(),
    });
}

/// The no-specimen displacement dropping to zero for 50 samples.
fn dropout(logs: &std::path::Path) {
    rewrite(logs, "no-specimen", 2, |k, v| match k {
        20_000..20_050 => "0".into(),
        _ => v.to_string(),
    });
}

/// Every channel of the no-specimen log frozen for 2 s.
fn frozen(logs: &std::path::Path) {
    let path = logs.join("no-specimen.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let held: Vec<String> = text
        .lines()
        .nth(20_001)
        .unwrap()
        .split(',')
        .map(String::from)
        .collect();
    for (col, value) in held.iter().enumerate().skip(1) {
        rewrite(logs, "no-specimen", col, |k, v| match k {
            20_000..22_000 => value.clone(),
            _ => v.to_string(),
        });
    }
}

/// A time column that starts again at 0 after 30 s in every log.
fn reset(logs: &std::path::Path) {
    rewrite_all(logs, 0, |k, v| match k {
        30_000.. => format!("{}", v.parse::<f64>().unwrap() - 30.0),
        _ => v.to_string(),
    });
}

/// Every log's displacement (mm) read through a cubic: x (1 + 0.003 (x /
/// 4 mm)^2), 0.3 % at the sweep's 4 mm, outside the loop.
fn cubic_reading(logs: &std::path::Path) {
    rewrite_all(logs, 2, |_, v| {
        let x = v.parse::<f64>().unwrap();
        format!("{}", x * (1.0 + 0.003 * (x / 4.0).powi(2)))
    });
}

/// Two time stamps swapped in every log.
fn swapped(logs: &std::path::Path) {
    rewrite_all(logs, 0, |k, v| match k {
        20_000 => "20.001".into(),
        20_001 => "20".into(),
        _ => v.to_string(),
    });
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
            name: "three adjacent corrupt displacement samples (+1.7 mm)",
            cause: Some(Class::Sample),
            logs: corrupt_stretch,
            ..BASE
        },
        Case {
            name: "a displacement stuck for 2 s",
            cause: Some(Class::Channel),
            logs: stuck,
            ..BASE
        },
        Case {
            name: "a displacement dropping to zero for 50 samples",
            cause: Some(Class::Channel),
            logs: dropout,
            ..BASE
        },
        Case {
            name: "every channel frozen for 2 s",
            cause: Some(Class::Channel),
            logs: frozen,
            ..BASE
        },
        Case {
            name: "the displacement inverted",
            cause: Some(Class::Channel),
            logs: |logs| rewrite_all(logs, 2, |_, v| negated(v)),
            ..BASE
        },
        Case {
            name: "the force inverted",
            cause: Some(Class::Channel),
            logs: |logs| rewrite_all(logs, 3, |_, v| negated(v)),
            ..BASE
        },
        Case {
            name: "a force in kN declared as N",
            cause: Some(Class::Units),
            edit: |s| {
                let f = "[channels.force]\ncolumn = \"force_kn\"\nunit = \"kN\"";
                assert!(s.contains(f), "{s}");
                s.replace(f, &f.replace("unit = \"kN\"", "unit = \"N\""))
            },
            ..BASE
        },
        Case {
            name: "a time column that starts again (a rate stated)",
            cause: Some(Class::TimeBase),
            logs: reset,
            edit: |s| {
                let t = "[channels.time]\ncolumn = \"time_s\"\nunit = \"s\"";
                assert!(s.contains(t), "{s}");
                s.replace(t, "[channels.time]\nsample_rate_hz = 1000.0")
            },
            ..BASE
        },
        Case {
            name: "two time stamps swapped",
            cause: Some(Class::TimeBase),
            logs: swapped,
            ..BASE
        },
        Case {
            name: "the valve's flow-pressure law, F_max 4.9 kN",
            cause: Some(Class::Nonlinear),
            rig: "supply_pressure_pa = 2.07e7\npiston_area_m2 = 2.387e-4",
            ..BASE
        },
        Case {
            name: "the valve's flow-pressure law, F_max 2.5 kN",
            cause: Some(Class::Nonlinear),
            rig: "supply_pressure_pa = 2.07e7\npiston_area_m2 = 1.2077e-4",
            ..BASE
        },
        Case {
            name: "a logged displacement 0.3 % cubic",
            cause: Some(Class::Channel),
            logs: cubic_reading,
            ..BASE
        },
        Case {
            name: "a 10-bit displacement",
            cause: Some(Class::Quantisation),
            sensor: "",
            bits: 10,
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
