//! The same specimen at two or more amplitudes: how its x1/u moves with
//! the amplitude, and which nonlinear candidate the movement fits. Each
//! run's x1/u is divided by the smallest-amplitude run's at the same bins,
//! so the rig's own misfit, the same in both, cancels; what is left is the
//! ratio of a candidate's describing functions at the two amplitudes. The
//! seals' friction weighs less as the velocity grows
//! ([`model::friction_factor`]), the valve's flow law more as the force
//! grows ([`model::flow::flow_factor`]), and a stiffening spring's
//! k + 3/4 k3 X^2 (the Duffing spring's describing function) more as the
//! displacement grows. Each candidate's one parameter is fitted to the
//! series by weighted least squares in log x1/u, and an F test against no
//! movement and the candidates' costs against each other say which fits.

use nalgebra::Complex;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use crate::fit::delay_significance::P_SIGNIFICANT;
use crate::model::{self, LinearSpecimen, RigParams, Seals};

/// One run of a series: its x1/u bins, their variance E|dH|^2 and the
/// displacement's amplitude X (m) at each.
#[derive(Debug, Clone, Copy)]
pub struct SeriesRun<'a> {
    pub id: &'a str,
    pub freq_hz: &'a [f64],
    pub h: &'a [Complex<f64>],
    pub variance: &'a [f64],
    pub amplitude_m: &'a [f64],
}

/// A nonlinear candidate an amplitude series can fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Movement {
    /// The seals' Coulomb friction: driven by the velocity.
    SealFriction,
    /// The servo-valve's flow-pressure law: driven by the force.
    FlowLaw,
    /// A spring that stiffens (or softens): driven by the displacement.
    Stiffening,
}

impl Movement {
    fn name(self) -> &'static str {
        match self {
            Movement::SealFriction => "the seals' friction",
            Movement::FlowLaw => "the valve's flow law",
            Movement::Stiffening => "a stiffening spring",
        }
    }

    /// The fitted parameter's symbol and unit in a sentence.
    fn symbol(self) -> (&'static str, &'static str) {
        match self {
            Movement::SealFriction => ("F", "N"),
            Movement::FlowLaw => ("F_max", "N"),
            Movement::Stiffening => ("k3", "N/m^3"),
        }
    }

    /// The fitted parameter's name as results give it.
    fn parameter(self) -> &'static str {
        match self {
            Movement::SealFriction => "coulomb_friction_n",
            Movement::FlowLaw => "max_force_n",
            Movement::Stiffening => "cubic_stiffness_n_per_m3",
        }
    }
}

/// One run of a series, against the series' smallest amplitude.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct AmplitudeRun {
    pub run: String,
    /// The displacement's amplitude (m): the largest over its bins, which a
    /// sweep reaches below the rig's bandwidth.
    pub amplitude_m: f64,
    /// The largest velocity amplitude 2 pi f X over its bins (m/s).
    pub peak_velocity_m_per_s: f64,
    /// The largest force amplitude |S(j 2 pi f)| X over its bins (N): none
    /// without a specimen.
    pub peak_force_n: f64,
    /// The bins it shares with the smallest amplitude's run (none for that
    /// run itself).
    pub bins: usize,
    /// x1/u's change from the smallest amplitude's, averaged over the shared
    /// bins with their weights: gain (%) and phase (degrees), each with its
    /// std; none for the smallest amplitude's run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub change: Option<Change>,
}

/// A change of x1/u in gain (%) and phase (degrees), with stds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Change {
    pub gain_pct: f64,
    pub gain_std_pct: f64,
    pub phase_deg: f64,
    pub phase_std_deg: f64,
}

/// One candidate fitted to a series.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct MovementFit {
    pub candidate: Movement,
    /// Its parameter: F (N), F_max (N) or k3 (N/m^3).
    pub parameter: String,
    /// The parameter and its std; none where the fit rests at no movement
    /// (F = 0, F_max infinite, k3 = 0).
    pub value: Option<f64>,
    pub std: Option<f64>,
    /// The weighted squared residual over its degrees of freedom.
    pub reduced_chi2: f64,
    /// The F statistic against no movement, and its p-value.
    pub f: f64,
    pub p_value: f64,
    /// The gain (%) and phase (degrees) change it predicts for each run
    /// after the first, averaged as the measured change is.
    pub predicted: Vec<[f64; 2]>,
}

/// A series: the same specimen at two or more amplitudes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct AmplitudeSeries {
    /// Its runs, smallest amplitude first (the reference).
    pub runs: Vec<AmplitudeRun>,
    /// The residual of no movement at all over its degrees of freedom
    /// (two per shared bin).
    pub linear_reduced_chi2: f64,
    pub dof: usize,
    pub candidates: Vec<MovementFit>,
    /// The candidate the movement fits, where one does significantly
    /// better than no movement and than the others.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fits: Option<Movement>,
    /// The finding in a sentence.
    pub finding: String,
}

/// Fewest shared bins a run is compared over.
const MIN_BINS: usize = 8;

/// A significant candidate is told from the best when its cost exceeds the
/// best's by this many of the best's reduced chi-square (an F statistic of
/// 10 on one degree of freedom: p about 0.002).
const TOLD_APART: f64 = 10.0;

/// log(x1/u) ratios of one run against the reference at their shared bins:
/// (f, X_run, X_ref, measured log ratio, weight 2 / var of it).
type Shared = Vec<(f64, f64, f64, Complex<f64>, f64)>;

/// The series' movement and which candidate fits it, with the rig
/// (at the runs' P gain) and the specimen the runs share. None with fewer
/// than two runs or no bins shared with the smallest amplitude's run.
pub fn series(
    rig: &RigParams,
    specimen: &LinearSpecimen,
    runs: &[SeriesRun<'_>],
) -> Option<AmplitudeSeries> {
    let mut order: Vec<&SeriesRun<'_>> = runs.iter().collect();
    order.sort_by(|a, b| largest(a.amplitude_m).total_cmp(&largest(b.amplitude_m)));
    let (reference, rest) = order.split_first()?;
    let shared: Vec<Shared> = rest.iter().map(|r| shared_bins(r, reference)).collect();
    let dof = 2 * shared.iter().map(Vec::len).sum::<usize>();
    if shared.iter().any(|s| s.len() < MIN_BINS) {
        return None;
    }
    let linear = cost(&shared, |_, _| Some(Complex::new(0.0, 0.0)))?;
    let candidates: Vec<MovementFit> = [
        Movement::SealFriction,
        Movement::FlowLaw,
        Movement::Stiffening,
    ]
    .into_iter()
    .filter_map(|c| fit_candidate(c, rig, specimen, &shared, linear, dof))
    .collect();
    let mut series = AmplitudeSeries {
        runs: std::iter::once(summary(reference, specimen, None, &[]))
            .chain(
                rest.iter()
                    .zip(&shared)
                    .map(|(r, s)| summary(r, specimen, Some(mean_change(s, |b| b.3)), s)),
            )
            .collect(),
        linear_reduced_chi2: linear / dof as f64,
        dof,
        candidates,
        fits: None,
        finding: String::new(),
    };
    let (fits, finding) = verdict(&series);
    series.fits = fits;
    series.finding = finding;
    Some(series)
}

/// The largest of `v` (0 when empty).
pub fn largest(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

/// The bins `run` shares with `reference` (the same frequency within a
/// millionth), with the log ratio of their x1/u and its weight.
fn shared_bins(run: &SeriesRun<'_>, reference: &SeriesRun<'_>) -> Shared {
    run.freq_hz
        .iter()
        .enumerate()
        .filter_map(|(i, &f)| {
            let j = crate::frf::bin_at(reference.freq_hz, f, 1e-6)?;
            let (a, b) = (run.h[i], reference.h[j]);
            let rel = run.variance[i] / a.norm_sqr() + reference.variance[j] / b.norm_sqr();
            (rel > 0.0 && rel.is_finite()).then(|| {
                (
                    f,
                    run.amplitude_m[i],
                    reference.amplitude_m[j],
                    (a / b).ln(),
                    2.0 / rel,
                )
            })
        })
        .collect()
}

/// The weighted squared residual of the measured log ratios against
/// `model`'s (its log factor at (f, X)); None where the model has none at
/// some bin (the flow law past F_max).
fn cost(shared: &[Shared], model: impl Fn(f64, f64) -> Option<Complex<f64>>) -> Option<f64> {
    let mut sum = 0.0;
    for s in shared {
        for &(f, x, x_ref, d, w) in s {
            let m = model(f, x)? - model(f, x_ref)?;
            sum += w * (d - m).norm_sqr();
        }
    }
    Some(sum)
}

/// log of candidate `c`'s factor on x1/u with parameter `theta` at
/// (f, X).
fn log_factor(
    c: Movement,
    theta: f64,
    rig: &RigParams,
    specimen: &LinearSpecimen,
    f_hz: f64,
    x: f64,
) -> Option<Complex<f64>> {
    let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f_hz);
    let (m, cc, k) = specimen.mck();
    let sp = s * s * m + s * cc + k;
    match c {
        Movement::SealFriction => {
            let seals = Seals {
                coulomb_friction_n: theta,
                piston_mass_kg: None,
                smoothing_velocity_m_per_s: None,
                seal_damping_ns_per_m: None,
            };
            Some(model::friction_factor(rig, specimen, &seals, x, f_hz).ln())
        }
        Movement::FlowLaw if theta > 0.0 => {
            model::flow::flow_factor(rig, s, sp, x, 1.0 / theta).map(|g| g.ln())
        }
        Movement::FlowLaw => Some(Complex::default()),
        Movement::Stiffening => {
            let q = |sp: Complex<f64>| (s + rig.a3_per_s) * sp + s * rig.a2_n_per_m;
            let d = |sp| (s + rig.beta1_per_s) * q(sp) + rig.a1b0_n_per_m_s2;
            Some((d(sp) / d(sp + 0.75 * theta * x * x)).ln())
        }
    }
}

/// Candidate `c`'s parameter fitted to the series: a scan over four decades
/// below the largest value the series could carry, refined by golden
/// section; its std from the cost's curvature, scaled by the reduced
/// chi-square where that exceeds 1. None where the candidate has nothing
/// to act on (the flow law or a stiffening spring without a specimen).
fn fit_candidate(
    c: Movement,
    rig: &RigParams,
    specimen: &LinearSpecimen,
    shared: &[Shared],
    linear: f64,
    dof: usize,
) -> Option<MovementFit> {
    let (m, _, k) = specimen.mck();
    let bins = || shared.iter().flatten();
    let top = match c {
        // The friction's describing load 4 F / (pi X) half the oil column's
        // a2 at the smallest amplitude.
        Movement::SealFriction => {
            let x = bins().map(|b| b.1.min(b.2)).fold(f64::INFINITY, f64::min);
            0.5 * rig.a2_n_per_m * std::f64::consts::PI * x / 4.0
        }
        // 1 / F_max up to the describing function's edge at the largest force.
        Movement::FlowLaw => {
            let force = bins()
                .map(|b| {
                    let w = 2.0 * std::f64::consts::PI * b.0;
                    let (_, cc, k) = specimen.mck();
                    Complex::new(k - m * w * w, cc * w).norm() * b.1.max(b.2)
                })
                .fold(0.0, f64::max);
            if force <= 0.0 {
                return None;
            }
            0.95 / force
        }
        // 3/4 k3 X^2 up to half of k at the largest amplitude.
        Movement::Stiffening => {
            let x = bins().map(|b| b.1.max(b.2)).fold(0.0, f64::max);
            if k <= 0.0 || x <= 0.0 {
                return None;
            }
            0.5 * k / (0.75 * x * x)
        }
    };
    let chi2 = |theta: f64| {
        cost(shared, |f, x| log_factor(c, theta, rig, specimen, f, x)).unwrap_or(f64::INFINITY)
    };
    let signs: &[f64] = if c == Movement::Stiffening {
        &[1.0, -1.0]
    } else {
        &[1.0]
    };
    let mut grid: Vec<f64> = vec![0.0];
    for &sign in signs {
        grid.extend((0..=40).map(|i| sign * top * 10f64.powf(-4.0 + 0.1 * i as f64)));
    }
    grid.sort_by(f64::total_cmp);
    let costs: Vec<f64> = grid.iter().map(|&t| chi2(t)).collect();
    let best = (0..grid.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
    let lo = grid[best.saturating_sub(1)];
    let hi = grid[(best + 1).min(grid.len() - 1)];
    let theta = golden(&chi2, lo, hi);
    let best_cost = chi2(theta);
    let reduced = best_cost / (dof - 1) as f64;
    let std = curvature_std(&chi2, theta, top) * reduced.max(1.0).sqrt();
    let f = ((linear - best_cost) / reduced).max(0.0);
    let p_value = FisherSnedecor::new(1.0, (dof - 1) as f64).map_or(1.0, |d| d.sf(f));
    let (value, std) = natural(c, theta, std);
    let predicted = shared
        .iter()
        .map(|s| {
            let ch = mean_change(s, |&(f, x, x_ref, ..)| {
                log_factor(c, theta, rig, specimen, f, x).unwrap_or_default()
                    - log_factor(c, theta, rig, specimen, f, x_ref).unwrap_or_default()
            });
            [ch.gain_pct, ch.phase_deg]
        })
        .collect();
    Some(MovementFit {
        candidate: c,
        parameter: c.parameter().to_string(),
        value,
        std,
        reduced_chi2: reduced,
        f,
        p_value,
        predicted,
    })
}

/// The parameter as results give it: F_max = 1 / theta for the flow law
/// (its std by first order); none at no movement.
fn natural(c: Movement, theta: f64, std: f64) -> (Option<f64>, Option<f64>) {
    if theta == 0.0 {
        return (None, None);
    }
    match c {
        Movement::FlowLaw => (Some(1.0 / theta), Some(std / (theta * theta))),
        _ => (Some(theta), Some(std)),
    }
}

/// The minimum of `g` on [lo, hi] by golden section, to 1e-6 of the
/// interval.
fn golden(g: &impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    let r = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (hi - r * (hi - lo), lo + r * (hi - lo));
    let (mut ga, mut gb) = (g(a), g(b));
    let width = hi - lo;
    while hi - lo > 1e-6 * width {
        if ga < gb {
            hi = b;
            (b, gb) = (a, ga);
            a = hi - r * (hi - lo);
            ga = g(a);
        } else {
            lo = a;
            (a, ga) = (b, gb);
            b = lo + r * (hi - lo);
            gb = g(b);
        }
    }
    0.5 * (lo + hi)
}

/// The std of the parameter from the cost's second derivative at `theta`,
/// chi2'' / 2 being the inverse variance; a one-sided difference where
/// `theta` is at or near 0 (the friction and the law have no negative
/// side).
fn curvature_std(g: &impl Fn(f64) -> f64, theta: f64, top: f64) -> f64 {
    let h = (1e-3 * theta.abs()).max(1e-6 * top);
    let second = if theta.abs() > 2.0 * h {
        (g(theta + h) - 2.0 * g(theta) + g(theta - h)) / (h * h)
    } else {
        (g(theta + 2.0 * h) - 2.0 * g(theta + h) + g(theta)) / (h * h)
    };
    if second > 0.0 {
        (2.0 / second).sqrt()
    } else {
        f64::INFINITY
    }
}

/// The weighted mean of a log ratio (`value` of each shared bin: the
/// measured one, or a candidate's) over the shared bins, as a gain (%) and
/// phase (degrees) change with the stds the measured one's weights give.
fn mean_change(
    s: &Shared,
    value: impl Fn(&(f64, f64, f64, Complex<f64>, f64)) -> Complex<f64>,
) -> Change {
    let (mut sum, mut weight) = (Complex::default(), 0.0);
    for b in s {
        sum += value(b) * b.4;
        weight += b.4;
    }
    let mean = sum / weight;
    let std = (1.0 / weight).sqrt();
    Change {
        gain_pct: 100.0 * mean.re.exp_m1(),
        gain_std_pct: 100.0 * std * mean.re.exp(),
        phase_deg: mean.im.to_degrees(),
        phase_std_deg: std.to_degrees(),
    }
}

/// A run's row: its amplitude, velocity and force, and its change.
fn summary(
    run: &SeriesRun<'_>,
    specimen: &LinearSpecimen,
    change: Option<Change>,
    shared: &[(f64, f64, f64, Complex<f64>, f64)],
) -> AmplitudeRun {
    let (m, c, k) = specimen.mck();
    let w = |f: f64| 2.0 * std::f64::consts::PI * f;
    let bins = run.freq_hz.iter().zip(run.amplitude_m);
    AmplitudeRun {
        run: run.id.to_string(),
        amplitude_m: largest(run.amplitude_m),
        peak_velocity_m_per_s: bins.clone().map(|(&f, &x)| w(f) * x).fold(0.0, f64::max),
        peak_force_n: bins
            .map(|(&f, &x)| Complex::new(k - m * w(f) * w(f), c * w(f)).norm() * x)
            .fold(0.0, f64::max),
        bins: shared.len(),
        change,
    }
}

/// The candidate the movement fits, if one does, and the finding.
fn verdict(s: &AmplitudeSeries) -> (Option<Movement>, String) {
    let amplitudes = s
        .runs
        .iter()
        .map(|r| format!("{} at {:.2} mm", r.run, 1e3 * r.amplitude_m))
        .collect::<Vec<_>>()
        .join(", ");
    let significant: Vec<&MovementFit> = s
        .candidates
        .iter()
        .filter(|c| c.p_value < P_SIGNIFICANT && c.value.is_some())
        .collect();
    let Some(best) = significant
        .iter()
        .min_by(|a, b| a.reduced_chi2.total_cmp(&b.reduced_chi2))
    else {
        return (
            None,
            format!(
                "{amplitudes}: x1/u does not move beyond its noise between these amplitudes (reduced chi-square {:.2} for no movement): no nonlinearity shows",
                s.linear_reduced_chi2
            ),
        );
    };
    let dof = (s.dof - 1) as f64;
    let alike: Vec<&&MovementFit> = significant
        .iter()
        .filter(|c| c.candidate != best.candidate)
        .filter(|c| (c.reduced_chi2 - best.reduced_chi2) * dof / best.reduced_chi2 < TOLD_APART)
        .collect();
    let value = |c: &MovementFit| {
        let (symbol, unit) = c.candidate.symbol();
        match (c.value, c.std) {
            (Some(v), Some(e)) => format!("{symbol} = {} +- {} {unit}", sig(v), sig(e)),
            _ => symbol.to_string(),
        }
    };
    if !alike.is_empty() {
        let names: Vec<String> = std::iter::once(best)
            .chain(alike.iter().copied())
            .map(|c| {
                format!(
                    "{} ({}, reduced chi-square {:.2})",
                    c.candidate.name(),
                    value(c),
                    c.reduced_chi2
                )
            })
            .collect();
        return (
            None,
            format!(
                "{amplitudes}: x1/u moves with the amplitude (reduced chi-square {:.2} for no movement), and {} fit it alike: the friction follows the velocity, the flow law the force and a spring the displacement, so a series without a specimen, or of another stiffness, tells them apart",
                s.linear_reduced_chi2,
                names.join(" and ")
            ),
        );
    }
    let others: Vec<String> = s
        .candidates
        .iter()
        .filter(|c| c.candidate != best.candidate)
        .map(|c| format!("{} {:.2}", c.candidate.name(), c.reduced_chi2))
        .collect();
    (
        Some(best.candidate),
        format!(
            "{amplitudes}: x1/u moves with the amplitude (reduced chi-square {:.2} for no movement) as {} would, {} (reduced chi-square {:.2}; {})",
            s.linear_reduced_chi2,
            best.candidate.name(),
            value(best),
            best.reduced_chi2,
            if others.is_empty() {
                "no other candidate applies".to_string()
            } else {
                others.join(", ")
            }
        ),
    )
}

/// `v` to three significant figures.
fn sig(v: f64) -> String {
    format!("{:.3e}", v)
        .parse::<f64>()
        .map(|r| {
            if r.abs() >= 1e-2 && r.abs() < 1e6 {
                format!("{r}")
            } else {
                format!("{r:e}")
            }
        })
        .unwrap_or_else(|_| v.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A series made from a candidate's own factor (the same sweep's bins,
    /// X falling as 1 / f from 4 and 1 mm, every bin's variance 1e-8 of
    /// |H|^2): each candidate's parameter comes back to 1e-4 where it made
    /// the series, and the series names it; the factor of no movement
    /// (the same H at both amplitudes) names none.
    #[test]
    fn each_candidate_is_found_in_a_series_it_made() {
        let rig = RigParams {
            beta1_per_s: 267.0,
            a1b0_n_per_m_s2: 2.412e9,
            a2_n_per_m: 7.881e5,
            a3_per_s: 16.118,
            p_gain: 1.0,
        };
        let spring = LinearSpecimen::Spring {
            stiffness_n_per_m: 116_640.0,
        };
        let freq: Vec<f64> = (1..=300).map(|i| 0.1 * i as f64).collect();
        let amplitude = |x0: f64| -> Vec<f64> { freq.iter().map(|f| x0 / f.max(1.0)).collect() };
        let (big, small) = (amplitude(4e-3), amplitude(1e-3));
        let linear: Vec<Complex<f64>> = freq
            .iter()
            .map(|&f| {
                let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
                let q = (s + rig.a3_per_s) * 116_640.0 + s * rig.a2_n_per_m;
                rig.a1b0_n_per_m_s2 / ((s + rig.beta1_per_s) * q + rig.a1b0_n_per_m_s2)
            })
            .collect();
        for (c, theta, truth) in [
            (Movement::SealFriction, 8.0, 8.0),
            (Movement::FlowLaw, 1.0 / 4000.0, 4000.0),
            (Movement::Stiffening, 1.5e8, 1.5e8),
        ] {
            let h = |x: &[f64]| -> Vec<Complex<f64>> {
                freq.iter()
                    .zip(x)
                    .zip(&linear)
                    .map(|((&f, &x), &g)| {
                        g * log_factor(c, theta, &rig, &spring, f, x).unwrap().exp()
                    })
                    .collect()
            };
            let (h_big, h_small) = (h(&big), h(&small));
            let var = |h: &[Complex<f64>]| -> Vec<f64> {
                h.iter().map(|v| 1e-8 * v.norm_sqr()).collect()
            };
            let (v_big, v_small) = (var(&h_big), var(&h_small));
            let runs = [
                SeriesRun {
                    id: "big",
                    freq_hz: &freq,
                    h: &h_big,
                    variance: &v_big,
                    amplitude_m: &big,
                },
                SeriesRun {
                    id: "small",
                    freq_hz: &freq,
                    h: &h_small,
                    variance: &v_small,
                    amplitude_m: &small,
                },
            ];
            let s = series(&rig, &spring, &runs).expect("a series");
            assert_eq!(s.runs[0].run, "small");
            assert_eq!(s.fits, Some(c), "{}", s.finding);
            let found = s.candidates.iter().find(|f| f.candidate == c).unwrap();
            let v = found.value.unwrap();
            assert!((v / truth - 1.0).abs() < 1e-4, "{c:?}: {v} against {truth}");
        }
        let var: Vec<f64> = linear.iter().map(|v| 1e-8 * v.norm_sqr()).collect();
        let runs = [
            SeriesRun {
                id: "big",
                freq_hz: &freq,
                h: &linear,
                variance: &var,
                amplitude_m: &big,
            },
            SeriesRun {
                id: "small",
                freq_hz: &freq,
                h: &linear,
                variance: &var,
                amplitude_m: &small,
            },
        ];
        let s = series(&rig, &spring, &runs).expect("a series");
        assert_eq!(s.fits, None, "{}", s.finding);
        assert!(s.finding.contains("does not move"), "{}", s.finding);
    }
}
