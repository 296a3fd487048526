//! The valid-data corpus: logs of the paper's rig (Table 3) as labs' DAQs
//! write them, each with nothing wrong: servoid's own excitations (a
//! square wave and a command limited in the controller among them), coarse
//! and fine converters at small and large amplitudes, rates from 200 Hz to
//! 10 kHz, records from 10 s to 20 minutes, time stamps jittered or rounded.
//! Each is simulated (a no-specimen run, springs k1 and k2 and the paper's
//! Exp1), analysed with the default settings, and must give every run ok,
//! the rig within 3.5 of its stated stds of the truth, and no warning but
//! those that say what the case holds. A check that refuses such a log, or
//! names a cause it lacks, fails here.

use std::path::Path;

use servoid::results::{Results, Status};
use servoid::warning::HEADLINE_MAX;

use crate::util::{PAPER_TRUTH, PaperSweep, analysed_simulation, rewrite_column};

/// One valid campaign: how it is simulated, what is done to its logs, and
/// the phrases of the warnings it may give (each a true statement about
/// it).
struct Case {
    name: &'static str,
    sweep: PaperSweep,
    logs: fn(&Path),
    may_say: &'static [&'static str],
}

fn untouched(_: &Path) {}

/// Each CSV log's column `col` rewritten by `f(sample, value)`.
fn rewrite(logs: &Path, col: usize, f: impl Fn(usize, f64) -> String) {
    for entry in std::fs::read_dir(logs).unwrap() {
        rewrite_column(&entry.unwrap().path(), col, |k, v| f(k, v.parse().unwrap()));
    }
}

/// Each time stamp late by up to 5 % of the 1 ms interval, as a DAQ that
/// stamps samples in software writes them.
fn late_stamps(logs: &Path) {
    rewrite(logs, 0, |k, t| {
        // A fixed scramble of k, uniform in [0, 1).
        let u = (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
        format!("{}", t + 5e-5 * (u as f64 / (1u64 << 53) as f64))
    });
}

/// 2048 Hz stamps written to the millisecond: some repeat.
fn stamps_to_the_millisecond(logs: &Path) {
    rewrite(logs, 0, |_, t| format!("{}", (t * 1e3).round() / 1e3));
}

/// 2048 Hz stamps written to a tenth of a millisecond.
fn stamps_to_a_tenth_of_a_millisecond(logs: &Path) {
    rewrite(logs, 0, |_, t| format!("{}", (t * 1e4).round() / 1e4));
}

fn sweep() -> PaperSweep {
    PaperSweep {
        log_format: "csv",
        validation: true,
        seed: 58,
        ..PaperSweep::default()
    }
}

fn cases() -> Vec<Case> {
    let case = |name, sweep| Case {
        name,
        sweep,
        logs: untouched,
        may_say: &[],
    };
    let mut out = vec![case("a 60 s chirp at 1 kHz", sweep())];
    // A random excitation starts and ends abruptly after its rests: the
    // seeds whose first or last sample departed most from its neighbours.
    for seed in [1, 2, 6, 7] {
        out.push(case(
            "random_band after a second of rest",
            PaperSweep {
                seed,
                excitation: Some(
                    "kind = \"random_band\"\nf_min_hz = 0.2\nf_max_hz = 35.0\nrms_m = 0.0015\nduration_s = 58.0\nlead_in_s = 1.0\nlead_out_s = 1.0",
                ),
                ..sweep()
            },
        ));
    }
    out.push(case(
        "a multisine of 60 tones between rests",
        PaperSweep {
            excitation: Some(
                "kind = \"multisine\"\nf_min_hz = 0.5\nf_max_hz = 35.0\nn_tones = 60\nrms_m = 0.0015\nduration_s = 30.0\nlead_in_s = 1.0\nlead_out_s = 1.0",
            ),
            ..sweep()
        },
    ));
    // A multisine whose record holds its period whole, started and stopped
    // in motion: its lines are sparse (one bin in 18), and the transient
    // and noise level come from the lines between them. With as few lines
    // a delay is hard to tell from none, which the rig's stds carry.
    out.push(Case {
        may_say: &["the data cannot tell \"none\""],
        ..case(
            "a multisine of 60 tones filling the record, no rest",
            PaperSweep {
                seed: 11,
                excitation: Some(
                    "kind = \"multisine\"\nf_min_hz = 0.1\nf_max_hz = 35.0\nn_tones = 60\nrms_m = 0.002\nduration_s = 30.0\nlead_in_s = 0.0\nlead_out_s = 0.0",
                ),
                ..sweep()
            },
        )
    });
    // A random-odd multisine with a low crest factor: its period repeated,
    // faded in over the first and out over the last, between rests.
    out.push(case(
        "a random-odd multisine, six 10 s periods between rests",
        PaperSweep {
            excitation: Some(
                "kind = \"odd_multisine\"\nf_min_hz = 0.5\nf_max_hz = 35.0\nperiod_s = 10.0\nrms_m = 0.0015\nduration_s = 60.0\nlead_in_s = 1.0\nlead_out_s = 1.0",
            ),
            ..sweep()
        },
    ));
    for (name, bits, amplitude_m) in [
        ("a 0.3 mm chirp through 18-bit converters", 18, 3e-4),
        ("a 4 mm chirp through 12-bit converters", 12, 4e-3),
        ("a 1 mm chirp through 16-bit converters", 16, 1e-3),
        ("a 4 mm chirp through 24-bit converters", 24, 4e-3),
    ] {
        out.push(case(
            name,
            PaperSweep {
                bits,
                amplitude_m,
                ..sweep()
            },
        ));
    }
    out.push(Case {
        may_say: &["coarse quantisation"],
        ..case(
            "a 0.3 mm chirp through 12-bit converters (3.4 steps RMS)",
            PaperSweep {
                bits: 12,
                amplitude_m: 3e-4,
                ..sweep()
            },
        )
    });
    // 200 and 300 Hz: the hold's aliases are 0.6 % and 0.2 % of the
    // no-specimen response at the band's 30 Hz top, which the fits model.
    for (name, fs) in [
        ("sampled at 200 Hz", 200.0),
        ("sampled at 300 Hz", 300.0),
        ("sampled at 2048 Hz", 2048.0),
        ("sampled at 10 kHz", 10_000.0),
    ] {
        out.push(case(
            name,
            PaperSweep {
                sample_rate_hz: fs,
                ..sweep()
            },
        ));
    }
    for (name, duration_s) in [("10 s long", 10.0), ("20 minutes long", 1200.0)] {
        out.push(case(
            name,
            PaperSweep {
                duration_s,
                ..sweep()
            },
        ));
    }
    // A square wave, as servo tuning plays it: plateaus at both extremes,
    // and a logged command of two levels whose quantisation is a gain
    // (half a step of 18 bits in 4 mm: up to 5e-5), which the joint fit
    // takes where the data show it.
    for seed in [58, 3] {
        out.push(case(
            "a square wave of 4 mm every 2 s",
            PaperSweep {
                seed,
                excitation: Some(
                    "kind = \"square\"\namplitude_m = 0.004\nperiod_s = 2.0\nduration_s = 58.0\nlead_in_s = 1.0\nlead_out_s = 1.0",
                ),
                ..sweep()
            },
        ));
    }
    out.push(Case {
        may_say: &["a limit set in the controller"],
        ..case(
            "a 4 mm chirp limited at 3 mm in the controller",
            PaperSweep {
                excitation: Some(
                    "kind = \"chirp\"\nlaw = \"quadratic\"\nf0_hz = 0.1\nf1_hz = 35.0\nduration_s = 58.0\namplitude_m = 0.004\nlimit_m = 0.003\nlead_in_s = 1.0\nlead_out_s = 1.0",
                ),
                ..sweep()
            },
        )
    });
    out.push(Case {
        logs: late_stamps,
        may_say: &["scatter about a uniform grid"],
        ..case("time stamps up to 5 % of an interval late", sweep())
    });
    out.push(Case {
        logs: stamps_to_the_millisecond,
        ..case(
            "2048 Hz stamps rounded to 1 ms",
            PaperSweep {
                sample_rate_hz: 2048.0,
                ..sweep()
            },
        )
    });
    out.push(Case {
        logs: stamps_to_a_tenth_of_a_millisecond,
        ..case(
            "2048 Hz stamps rounded to 0.1 ms",
            PaperSweep {
                sample_rate_hz: 2048.0,
                ..sweep()
            },
        )
    });
    out
}

/// The case simulated, its logs touched, and analysed as the generated
/// manifest has it (the defaults and the band).
fn analysed(case: &Case) -> Results {
    analysed_simulation(&case.sweep.text(), case.logs, |text| text)
}

/// What is wrong with a case's results, if anything.
fn faults(case: &Case, r: &Results) -> Vec<String> {
    let mut out = Vec::new();
    for run in &r.runs {
        if run.status != Status::Ok {
            out.push(format!("run {} failed: {:?}", run.id, run.error));
        }
    }
    match &r.rig {
        None => out.push("no rig".into()),
        Some(rig) => {
            for ((name, truth), e) in PAPER_TRUTH
                .iter()
                .zip([&rig.beta1, &rig.a1b0, &rig.a2, &rig.a3])
            {
                let z = (e.value - truth) / e.std.unwrap_or(f64::NAN);
                if z.is_nan() || z.abs() > 3.5 {
                    out.push(format!(
                        "{name} {:+.3} % ({z:+.1} stds)",
                        100.0 * (e.value / truth - 1.0)
                    ));
                }
            }
        }
    }
    let warnings = r.warnings.iter().map(|w| ("campaign", w)).chain(
        r.runs
            .iter()
            .flat_map(|run| run.warnings.iter().map(|w| (run.id.as_str(), w))),
    );
    for (at, w) in warnings {
        if !case.may_say.iter().any(|phrase| w.contains(phrase)) {
            out.push(format!("{at}: {w:#}"));
        }
        if w.headline.chars().count() > HEADLINE_MAX {
            out.push(format!(
                "{at}: a headline over {HEADLINE_MAX} characters: {w}"
            ));
        }
    }
    out
}

/// Every case of the corpus runs clean (`faults` names what failed).
#[test]
fn valid_logs_run_without_a_false_refusal_or_cause() {
    use rayon::prelude::*;
    let cases = cases();
    let found: Vec<(usize, Vec<String>)> = cases
        .par_iter()
        .enumerate()
        .map(|(i, c)| (i, faults(c, &analysed(c))))
        .collect();
    let failed: Vec<String> = found
        .iter()
        .filter(|(_, f)| !f.is_empty())
        .map(|(i, f)| {
            format!(
                "{} (seed {}):\n  {}",
                cases[*i].name,
                cases[*i].sweep.seed,
                f.join("\n  ")
            )
        })
        .collect();
    assert!(failed.is_empty(), "{}", failed.join("\n\n"));
}
