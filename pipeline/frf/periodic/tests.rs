//! Steady periods found where they were made, and the levels of a linear
//! and a distorting response told apart.

use rand_distr::{Distribution, StandardNormal};

use super::*;
use crate::simulate::excitation::{Excitation, Padding, generate};
use crate::simulate::seeded_rng;

const FS: f64 = 1000.0;

/// A 5 s odd multisine over 0.5-30 Hz, 8 periods (the first fading in,
/// the last out) between 2 s of rest: the steady stretch is the 6 periods
/// between the fades.
fn command() -> Vec<f64> {
    let exc = Excitation::OddMultisine {
        f_min_hz: 0.5,
        f_max_hz: 30.0,
        rms_m: 1e-3,
        period_s: 5.0,
        duration_s: 40.0,
        seed: 3,
    };
    generate(
        &exc,
        FS,
        Padding {
            lead_in_s: 2.0,
            lead_out_s: 2.0,
        },
    )
    .unwrap()
}

#[test]
fn the_steady_periods_are_those_between_the_fades() {
    let u = command();
    let s = steady_periods(&u, FS, 0.5).expect("periodic");
    assert_eq!(s.period, 5000);
    assert_eq!(s.count, 6);
    assert_eq!(s.start, 2000 + 5000);
}

/// A command sampled far above its lines (2 s periods of lines up to
/// 3 Hz at 2,048 Hz, 84 of them between 1 s of rest) correlates within
/// 1e-3 of its best a sample off the period: the period is still found
/// to the sample.
#[test]
fn an_oversampled_command_has_its_period_to_the_sample() {
    let exc = Excitation::OddMultisine {
        f_min_hz: 0.5,
        f_max_hz: 3.0,
        rms_m: 1e-3,
        period_s: 2.0,
        duration_s: 168.0,
        seed: 3,
    };
    let padding = Padding {
        lead_in_s: 1.0,
        lead_out_s: 1.0,
    };
    let u = generate(&exc, 2048.0, padding).unwrap();
    let s = steady_periods(&u, 2048.0, 0.5).expect("periodic");
    assert_eq!((s.period, s.count), (4096, 82));
}

/// A logged command with noise (a thousandth of its RMS, independent
/// sample to sample) still shows its steady periods: they repeat to the
/// noise, the fades do not.
#[test]
fn a_noisy_logged_command_shows_its_steady_periods() {
    let mut rng = seeded_rng(4, "frf/periodic/tests");
    let u: Vec<f64> = command()
        .iter()
        .map(|v| {
            let e: f64 = StandardNormal.sample(&mut rng);
            v + 1e-6 * e
        })
        .collect();
    let s = steady_periods(&u, FS, 0.5).expect("periodic");
    assert_eq!((s.period, s.count), (5000, 6));
    assert!(s.start.abs_diff(7000) <= 250, "start {}", s.start);
}

/// A rest longer than a period repeats itself too: it is not taken for
/// the steady periods.
#[test]
fn a_long_rest_is_not_a_steady_stretch() {
    let mut u = vec![0.0; 30_000];
    u.extend(command());
    let s = steady_periods(&u, FS, 0.5).expect("periodic");
    assert_eq!((s.start, s.count), (30_000 + 7000, 6));
}

#[test]
fn a_sweep_or_noise_has_no_steady_periods() {
    let chirp = generate(
        &Excitation::Chirp {
            law: crate::simulate::excitation::ChirpLaw::Linear,
            f0_hz: 0.5,
            f1_hz: 30.0,
            duration_s: 40.0,
            amplitude_m: 1e-3,
        },
        FS,
        Padding::default(),
    )
    .unwrap();
    assert_eq!(steady_periods(&chirp, FS, 0.5), None);
    let mut rng = seeded_rng(1, "frf/periodic/tests");
    let noise: Vec<f64> = (0..40_000)
        .map(|_| StandardNormal.sample(&mut rng))
        .collect();
    assert_eq!(steady_periods(&noise, FS, 0.5), None);
}

/// A first-order lag of the command with white noise: the empty lines
/// hold the noise floor (their power over it within 4 of its scatter,
/// 1 / sqrt(lines)); with a cubic term they hold far more.
#[test]
fn distortion_shows_on_the_empty_lines_and_only_there() {
    let u = command();
    let s = steady_periods(&u, FS, 0.5).unwrap();
    let mut rng = seeded_rng(2, "frf/periodic/tests");
    let respond = |cubic: f64, rng: &mut rand_chacha::ChaCha8Rng| -> Vec<f64> {
        let a = (-2.0 * std::f64::consts::PI * 10.0 / FS).exp();
        let mut state = 0.0;
        u.iter()
            .map(|&v| {
                let drive = v + cubic * v * v * v;
                state = a * state + (1.0 - a) * drive;
                let e: f64 = StandardNormal.sample(rng);
                state + 1e-6 * e
            })
            .collect()
    };
    let linear = levels(&u, &respond(0.0, &mut rng), s, FS, (0.5, 30.0)).unwrap();
    let scatter = 1.0 / (linear.empty as f64).sqrt();
    let ratio = linear.distortion_to_noise();
    assert!(
        (ratio - 1.0).abs() < 4.0 * scatter,
        "linear: {ratio} (scatter {scatter})"
    );
    assert!(linear.output > 1e4 * linear.noise);
    let cubic = levels(&u, &respond(2e5, &mut rng), s, FS, (0.5, 30.0)).unwrap();
    assert!(
        cubic.distortion_to_noise() > 100.0,
        "cubic: {}",
        cubic.distortion_to_noise()
    );
}

/// A command longer than the search transforms (1.2 M samples: every
/// second sample searched) with an odd period of 3,001 samples: the
/// period is found to the sample, and the steady stretch with it.
#[test]
fn a_long_log_is_searched_on_fewer_samples_and_its_period_found_exactly() {
    let exc = Excitation::OddMultisine {
        f_min_hz: 0.5,
        f_max_hz: 30.0,
        rms_m: 1e-3,
        period_s: 3.001,
        duration_s: 3.001 * 400.0,
        seed: 5,
    };
    let u = generate(&exc, FS, Padding::default()).unwrap();
    assert!(u.len() > SCAN, "{} samples", u.len());
    let s = steady_periods(&u, FS, 0.5).expect("periodic");
    assert_eq!((s.period, s.count, s.start), (3001, 398, 3001));
}
