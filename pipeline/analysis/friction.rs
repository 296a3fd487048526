//! The seals' friction corrected for the describing function's bias by
//! indirect inference (Gourieroux, Monfort & Renault 1993, J. Appl.
//! Econometrics 8): the fitted rig is simulated through each
//! identification run's own command, the simulated logs go through the
//! same FRF estimate and joint fit, and the friction that fit finds against
//! the friction simulated is the estimator's bias there, in proportion to
//! the friction (docs/accuracy.md). The bias grows as the friction reverses
//! more sharply, by its zero-crossing width v0, which the FRFs do not see:
//! the rig is simulated at each of [`WIDTHS_M_PER_S`] (or at the width the
//! manifest states), the friction reported is the middle of the corrected
//! values, and their half-range is added to its std.

use rayon::prelude::*;

use super::log_stage::{LogStageError, fit_data_with};
use crate::identify::FitData;
use crate::identify::bins::Bins;
use crate::identify::joint::{self, JointFit, JointIdentification, JointOptions, JointRun, Place};
use crate::ingest::Log;
use crate::manifest::{Campaign, Role, RunPlan};
use crate::results::{FrictionCorrection, JointResult, WidthCorrection};
use crate::simulate::ode::Integrator;
use crate::simulate::plant::{self, ActuatorFriction, PlantSpec, Unmodelled, ValveMode};
use crate::warning::Warning;

/// The zero-crossing widths v0 (m/s) the fitted rig is simulated at where
/// the manifest states none: from a seal that reverses within a quarter of
/// a millimetre per second to one that rounds off over 4 mm/s, the range
/// over which an 8 N friction's bias moves from -13 to -7 % (docs/accuracy.md).
pub const WIDTHS_M_PER_S: [f64; 3] = [2.5e-4, 1e-3, 4e-3];

/// The chosen fit's friction corrected for its bias, where it has one and
/// every fitted FRF is an identification run's displacement (`plans`, in
/// the order of `ident.runs`). None where the fit has no friction or no
/// moving mass to simulate it on (a massless spring without the piston's
/// mass), or where a simulation or its refit fails.
pub fn corrected(
    campaign: &Campaign,
    plans: &[&RunPlan],
    ident: &JointIdentification<'_>,
    opts: &JointOptions,
) -> Option<FrictionCorrection> {
    let fit = ident.selection.fit()?;
    let (friction, std) = (fit.friction_n?, friction_std(fit)?);
    if !simulable(plans, ident, fit) || friction <= 0.0 {
        return None;
    }
    let widths = widths(opts);
    // The bias is in proportion to F (-6.6 and -6.7 % at 7.69 and 8 N; a
    // secant step through a second refit at F^2 / F' moved the suite's
    // frictions by under 0.1 %), so the friction whose fit reads F is
    // F^2 / F'.
    let cases: Vec<Case> = widths
        .iter()
        .map(|&v0| Case {
            friction_n: friction,
            smoothing_m_per_s: v0,
            max_force_n: fit.max_force_n,
        })
        .collect();
    let mut rows = Vec::with_capacity(widths.len());
    for (&v0, refit) in widths
        .iter()
        .zip(refits(campaign, plans, ident, opts, &cases)?)
    {
        let refit = refit.friction_n.filter(|&r| r > 0.0)?;
        rows.push(WidthCorrection {
            smoothing_m_per_s: v0,
            refit_n: refit,
            corrected_n: friction * friction / refit,
        });
    }
    let lo = rows
        .iter()
        .map(|r| r.corrected_n)
        .fold(f64::INFINITY, f64::min);
    let hi = rows.iter().map(|r| r.corrected_n).fold(0.0, f64::max);
    let value = 0.5 * (lo + hi);
    Some(FrictionCorrection {
        describing_function_n: friction,
        describing_function_std_n: std,
        value_n: value,
        std_n: std * value / friction,
        width_std_n: 0.5 * (hi - lo),
        widths: rows,
    })
}

/// Whether every fitted FRF (`plans`, one per FRF) is an identification
/// run's, which can be simulated through its own log (a validation run's
/// FRFs in the fit cannot), with a moving mass for the friction to act on:
/// the specimen's or the piston's.
fn simulable(plans: &[&RunPlan], ident: &JointIdentification<'_>, fit: &JointFit) -> bool {
    plans.len() == ident.runs.len()
        && plans.iter().all(|p| {
            p.role != Role::Validation
                && p.specimen
                    .linear()
                    .is_some_and(|s| s.mck().0 + fit.piston_mass_kg.unwrap_or(0.0) > 0.0)
        })
}

/// The widths v0 (m/s) simulated: the manifest's, else [`WIDTHS_M_PER_S`].
fn widths(opts: &JointOptions) -> Vec<f64> {
    match opts.friction_smoothing_m_per_s {
        Some(v0) => vec![v0],
        None => WIDTHS_M_PER_S.to_vec(),
    }
}

/// The flow law the chosen fit took beside the friction, where it is what
/// the friction's describing function leaves and not the valve's: the
/// fitted rig simulated with the friction alone at each width, fitted
/// again with the law freed, reads an F_max too, and the data's 1 / F_max
/// is within 3 of its stds of the largest such reading. Returns the
/// data's F_max and the simulations' smallest; None where the law is not
/// fitted beside friction, the nameplate gives F_max, or the rig cannot be
/// simulated.
pub fn law_artifact(
    campaign: &Campaign,
    plans: &[&RunPlan],
    ident: &JointIdentification<'_>,
    opts: &JointOptions,
) -> Option<(f64, f64)> {
    let fit = ident.selection.fit()?;
    let k = fit.names.iter().position(|n| *n == joint::FLOW_LAW)?;
    let (friction, max_force) = (fit.friction_n?, fit.max_force_n?);
    if opts.max_force_nameplate_n.is_some() || !simulable(plans, ident, fit) {
        return None;
    }
    let cases: Vec<Case> = widths(opts)
        .into_iter()
        .map(|v0| Case {
            friction_n: friction,
            smoothing_m_per_s: v0,
            max_force_n: None,
        })
        .collect();
    // A refit that finds no law (or fails) reads 1 / F_max = 0.
    let read = refits(campaign, plans, ident, opts, &cases)?
        .iter()
        .map(|r| r.max_force_n.map_or(0.0, |f| 1.0 / f))
        .fold(0.0, f64::max);
    let (kappa, std) = (1.0 / max_force, fit.std[k] / (max_force * max_force));
    (read > 0.0 && kappa < read + 3.0 * std).then(|| (max_force, 1.0 / read))
}

/// `c` into `result`: the friction parameter corrected, with the width's
/// spread in its total std, and the friction's warning saying so.
pub fn apply(c: FrictionCorrection, result: &mut JointResult, warnings: &mut [Warning]) {
    if let Some(p) = result
        .parameters
        .iter_mut()
        .find(|p| p.name == joint::FRICTION)
    {
        p.value = c.value_n;
        p.std = c.std_n;
        p.correction_std = Some(c.width_std_n);
        p.total_std = c.std_n.hypot(c.width_std_n);
    }
    if let Some(w) = warnings
        .iter_mut()
        .find(|w| w.headline.starts_with(FRICTION_HEADLINE))
    {
        w.headline = format!("{FRICTION_HEADLINE}: F = {:.1} N fitted", c.value_n);
        let widths = match c.widths.as_slice() {
            [one] => format!(
                "at the stated zero-crossing width {} mm/s",
                1e3 * one.smoothing_m_per_s
            ),
            _ => format!(
                "over the zero-crossing widths the FRFs do not see, {}-{} mm/s, whose spread, +- {:.3} N, is in its std",
                1e3 * WIDTHS_M_PER_S[0],
                1e3 * WIDTHS_M_PER_S[WIDTHS_M_PER_S.len() - 1],
                c.width_std_n
            ),
        };
        w.detail.push_str(&format!(
            ". That F is the describing function's, low in the closed loop (the piston's motion at each reversal is not the sinusoid it assumes); the fitted rig simulated through the runs' own commands and fitted again finds {}, so the friction is taken as F = {:.3} +- {:.3} N, {widths}",
            c.widths
                .iter()
                .map(|r| format!("{:.3} N at {} mm/s", r.refit_n, 1e3 * r.smoothing_m_per_s))
                .collect::<Vec<_>>()
                .join(", "),
            c.value_n,
            c.std_n.hypot(c.width_std_n),
        ));
    }
    result.friction_correction = Some(c);
}

/// How the friction's warning begins (`analysis::joint`).
pub const FRICTION_HEADLINE: &str = "rig: seal friction, not linear at this amplitude";

/// What the fitted rig is simulated with beyond its linear part: the
/// friction F tanh(v / v0) and, where given, the flow law's F_max.
#[derive(Debug, Clone, Copy)]
struct Case {
    friction_n: f64,
    smoothing_m_per_s: f64,
    max_force_n: Option<f64>,
}

/// The chosen fit fitted again from its optimum on every identification
/// run simulated with each of `cases`; None where a simulation, its log
/// stage or its refit fails.
fn refits(
    campaign: &Campaign,
    plans: &[&RunPlan],
    ident: &JointIdentification<'_>,
    opts: &JointOptions,
    cases: &[Case],
) -> Option<Vec<JointFit>> {
    let fit = ident.selection.fit()?;
    // Each run's log read once and every case simulated through it, side
    // by side, gathered in (run, case) order: the same bits on any number
    // of threads.
    let simulated: Vec<Result<Option<Vec<Option<FitData>>>, LogStageError>> = plans
        .par_iter()
        .map(|&p| {
            fit_data_with(campaign, p, cases.len(), |log, c| {
                simulate(fit, p, cases[c], log)
            })
        })
        .collect();
    let by_run: Vec<Vec<FitData>> = simulated
        .into_iter()
        .map(|r| r.ok().flatten()?.into_iter().collect::<Option<Vec<_>>>())
        .collect::<Option<_>>()?;
    (0..cases.len())
        .map(|c| {
            let data: Vec<&FitData> = by_run.iter().map(|run| &run[c]).collect();
            let aligned: Vec<Aligned> = ident
                .runs
                .iter()
                .zip(&data)
                .map(|(r, &d)| align(r, d))
                .collect();
            let runs: Vec<JointRun<'_>> = ident
                .runs
                .iter()
                .zip(&aligned)
                .map(|(r, a)| JointRun {
                    bins: Bins::held(&a.freq_hz, &a.h, &a.variance, a.amplitude_m.as_deref()),
                    ..*r
                })
                .collect();
            joint::refit(&runs, fit, opts).ok()
        })
        .collect()
}

/// The friction's statistical std in `fit`.
fn friction_std(fit: &JointFit) -> Option<f64> {
    let i = fit.names.iter().position(|n| *n == joint::FRICTION)?;
    fit.std.get(i).copied()
}

/// A simulated run's bins at the measured run's: its x1/u where the
/// simulation has the bin, with the measured variance and amplitude, so
/// the refit weighs each bin as the fit did.
struct Aligned {
    freq_hz: Vec<f64>,
    h: Vec<nalgebra::Complex<f64>>,
    variance: Vec<f64>,
    amplitude_m: Option<Vec<f64>>,
}

fn align(measured: &JointRun<'_>, sim: &FitData) -> Aligned {
    let measured = measured.bins.all();
    let mut a = Aligned {
        freq_hz: Vec::new(),
        h: Vec::new(),
        variance: Vec::new(),
        amplitude_m: measured.amplitude_m.as_ref().map(|_| Vec::new()),
    };
    for (k, &f) in measured.freq_hz.iter().enumerate() {
        let Some(j) = crate::frf::bin_at(&sim.freq_hz, f, 1e-9) else {
            continue;
        };
        a.freq_hz.push(f);
        a.h.push(sim.h[j]);
        a.variance.push(measured.variance[k]);
        if let (Some(out), Some(x)) = (a.amplitude_m.as_mut(), &measured.amplitude_m) {
            out.push(x[k]);
        }
    }
    a
}

/// The fitted rig's displacement through `log`'s command with `case`'s
/// friction and flow law: the rig at the run's P gain with the chosen
/// structure's mode at its place, the piston's mass, the seals' damping,
/// the flow law where fitted, and the sensor's delay. The command's first
/// sample is the rest the rig starts from (its static response added).
fn simulate(fit: &JointFit, plan: &RunPlan, case: Case, log: &Log) -> Option<Vec<f64>> {
    let mode = fit.mode.map(|(hz, zeta)| ValveMode {
        natural_frequency_hz: hz,
        damping_ratio: zeta,
    });
    let at = |p: Place| mode.filter(|_| fit.structure.place() == Some(p));
    let rig = fit.rig.at_p_gain(plan.p_gain);
    let spec = PlantSpec {
        rig,
        specimen: plan.specimen,
        unmodelled: Unmodelled {
            valve_mode: at(Place::Loop),
            command_mode: at(Place::Command),
            measurement_mode: at(Place::Measurement),
            piston_mass_kg: fit.piston_mass_kg,
            actuator_friction: Some(ActuatorFriction {
                coulomb_force_n: case.friction_n,
                smoothing_velocity_m_per_s: case.smoothing_m_per_s,
                viscous_ns_per_m: fit.seal_damping_ns_per_m.unwrap_or(0.0).max(0.0),
            }),
            max_force_n: case.max_force_n,
        },
    };
    let u0 = *log.command_m.first()?;
    let u: Vec<f64> = log.command_m.iter().map(|v| v - u0).collect();
    let r = plant::simulate(
        &spec,
        &u,
        log.sample_rate_hz,
        [fit.delay_s.max(0.0), 0.0],
        Integrator::default(),
    )
    .ok()?;
    // x1/u at rest: a1b0 / (a1b0 + beta1 a3 k) (Eq. 17 at s = 0).
    let k = plan.specimen.linear()?.mck().2;
    let gain = rig.a1b0_n_per_m_s2 / (rig.a1b0_n_per_m_s2 + rig.beta1_per_s * rig.a3_per_s * k);
    Some(r.x1_m.iter().map(|x| x + gain * u0).collect())
}
