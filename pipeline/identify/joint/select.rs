//! The model structure chosen by the data: the paper's model, a delay, a
//! piston's mass, a mode in the loop, the command path or the
//! measurement path, and the loop's mode with the piston. Nested
//! structures are chosen by the extra-sum-of-squares F test at
//! [`P_SIGNIFICANT`] (scaled by the larger fit's residual scatter), the
//! places among themselves by AIC; the seals' damping and the logged
//! command's gain are freed on the chosen structure where the F test takes
//! them. Every usable candidate's Schwarz weight spreads its rig into the
//! chosen fit's covariance ([`StructureSpread`]), counting a difference
//! only beyond twice what two fits of the same data differ by ([`HAUSMAN_Z`],
//! Hausman 1978). The derivation, the weights and the starts:
//! docs/methods.md, "The joint fit".

use nalgebra::Complex;
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use super::{
    FitError, JointFit, JointOptions, JointProblem, JointRun, Leg, Output, Point, Structure,
    finish, joint_fit, joint_fit_params, joint_fit_staged, problem, rig_theta, settle,
};
use crate::identify::Estimate;
use crate::model::RigParams;

pub use crate::fit::delay_significance::P_SIGNIFICANT;

/// How the structure is chosen: `identification.joint.structure`, "auto"
/// or one of [`Structure`]'s names.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Choice {
    /// By the F tests above.
    #[default]
    Auto,
    /// As the manifest fixes it; flagged when the data would choose another
    /// or reject it.
    Fixed(Structure),
}

impl Choice {
    /// Every value the manifest accepts, as it spells them.
    const NAMES: [&'static str; 8] = [
        "auto",
        Structure::Plain.as_str(),
        Structure::Delay.as_str(),
        Structure::DelayValve.as_str(),
        Structure::DelayCommand.as_str(),
        Structure::DelayMeasurement.as_str(),
        Structure::DelayPiston.as_str(),
        Structure::DelayValvePiston.as_str(),
    ];
}

impl Serialize for Choice {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Choice::Auto => s.serialize_str(Choice::NAMES[0]),
            Choice::Fixed(structure) => structure.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for Choice {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        if name == Choice::NAMES[0] {
            return Ok(Choice::Auto);
        }
        Structure::ALL
            .into_iter()
            .find(|s| s.as_str() == name)
            .map(Choice::Fixed)
            .ok_or_else(|| serde::de::Error::unknown_variant(&name, &Choice::NAMES))
    }
}

impl JsonSchema for Choice {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "JointStructureChoice".into()
    }

    fn json_schema(generator: &mut schemars::SchemaGenerator) -> schemars::Schema {
        let fixed = generator.subschema_for::<Structure>();
        schemars::json_schema!({
            "description": "How the joint fit's structure is chosen: by the data, or fixed.",
            "anyOf": [
                {
                    "description": "Chosen by the data among the structures (nested F tests; among the modes at different places, the lowest cost).",
                    "type": "string",
                    "const": "auto"
                },
                fixed
            ]
        })
    }
}

/// The F test of a structure against the one chosen before it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FTest {
    pub against: Structure,
    pub f: f64,
    pub p_value: f64,
}

/// A structure's fit, or why there is none to use.
#[derive(Debug)]
pub struct Candidate {
    pub structure: Structure,
    pub fit: Result<JointFit, FitError>,
    /// Why the fit is not usable although it ran: not converged, or not a
    /// physical rig.
    pub unusable: Option<String>,
    pub f_test: Option<FTest>,
}

impl Candidate {
    /// The fit when it is usable.
    pub fn usable(&self) -> Option<&JointFit> {
        self.fit.as_ref().ok().filter(|_| self.unusable.is_none())
    }

    /// Bayesian information criterion of the Gaussian likelihood with the
    /// noise known: cost + p ln(2 N).
    pub fn bic(&self) -> Option<f64> {
        let fit = self.fit.as_ref().ok()?;
        let n = (fit.dof + fit.params.len()) as f64;
        Some(fit.cost + fit.params.len() as f64 * n.ln())
    }
}

/// The candidates and the choice among them.
#[derive(Debug)]
pub struct Selection {
    pub candidates: Vec<Candidate>,
    /// What the data choose (None when no candidate is usable).
    pub auto: Option<Structure>,
    /// What is used: `auto`, or the manifest's structure.
    pub chosen: Option<Structure>,
    pub choice: Choice,
}

impl Selection {
    /// The spread of the rig among the candidates about the chosen fit's
    /// (docs/methods.md, "The joint fit"), when a structure is chosen.
    pub fn spread(&self) -> Option<StructureSpread> {
        let chosen = self.fit()?;
        let usable: Vec<(usize, &JointFit)> = self
            .candidates
            .iter()
            .enumerate()
            .filter_map(|(i, c)| Some((i, c.usable()?)))
            .collect();
        let c_hat = usable
            .iter()
            .map(|(_, f)| f.cost / f.dof as f64)
            .fold(f64::INFINITY, f64::min)
            .max(1.0);
        // Schwarz's penalty, ln of the number of real residuals per
        // parameter (docs/methods.md, "The joint fit").
        let qaic = |f: &JointFit| {
            let n = (f.dof + f.params.len()) as f64;
            f.cost / c_hat + f.params.len() as f64 * n.ln()
        };
        let best = usable
            .iter()
            .map(|(_, f)| qaic(f))
            .fold(f64::INFINITY, f64::min);
        let mut weights = vec![0.0; self.candidates.len()];
        for (i, f) in &usable {
            weights[*i] = (-0.5 * (qaic(f) - best)).exp();
        }
        let total: f64 = weights.iter().sum();
        if total > 0.0 {
            weights.iter_mut().for_each(|w| *w /= total);
        }
        let mut covariance = [[0.0; 4]; 4];
        let mut rivals = Vec::new();
        for (i, f) in &usable {
            let w = weights[*i];
            let d: [f64; 4] = std::array::from_fn(|k| f.params[k] - chosen.params[k]);
            // Only what statistics do not explain (docs/methods.md, "The joint fit"): a
            // difference within HAUSMAN_Z of its statistical std adds
            // nothing, a larger one its square less |var_i - var_chosen|.
            let noise: [f64; 4] =
                std::array::from_fn(|k| (f.std[k].powi(2) - chosen.std[k].powi(2)).abs());
            let beyond: [bool; 4] =
                std::array::from_fn(|k| d[k] * d[k] > HAUSMAN_Z * HAUSMAN_Z * noise[k]);
            let excess: [f64; 4] = std::array::from_fn(|k| {
                if beyond[k] {
                    d[k] * (1.0 - noise[k] / (d[k] * d[k])).max(0.0).sqrt()
                } else {
                    0.0
                }
            });
            for (a, row) in covariance.iter_mut().enumerate() {
                for (b, cell) in row.iter_mut().enumerate() {
                    *cell += w * excess[a] * excess[b];
                }
            }
            if f.structure == chosen.structure || w < WEIGHT_FLOOR {
                continue;
            }
            let moved: Vec<Moved> = (0..4)
                .filter_map(|k| {
                    let combined = (f.std[k].powi(2) + chosen.std[k].powi(2)).sqrt();
                    let z = d[k] / combined;
                    (z.abs() > 1.0 && beyond[k]).then(|| Moved {
                        parameter: k,
                        relative: d[k] / chosen.params[k],
                        z,
                    })
                })
                .collect();
            if !moved.is_empty() {
                rivals.push(Rival {
                    structure: f.structure,
                    weight: w,
                    moved,
                });
            }
        }
        let std = std::array::from_fn(|k| covariance[k][k].sqrt());
        Some(StructureSpread {
            weights,
            c_hat,
            std,
            covariance,
            rivals,
        })
    }

    /// The chosen structure's fit.
    pub fn fit(&self) -> Option<&JointFit> {
        let chosen = self.chosen?;
        self.candidates
            .iter()
            .find(|c| c.structure == chosen)
            .and_then(|c| c.fit.as_ref().ok())
    }

    pub fn candidate(&self, s: Structure) -> Option<&Candidate> {
        self.candidates.iter().find(|c| c.structure == s)
    }
}

/// How many of its statistical stds (sqrt |var_i - var_chosen|) a
/// candidate's difference from the chosen rig must exceed to count in the
/// structure std or as a rival (docs/methods.md, "The joint fit").
pub const HAUSMAN_Z: f64 = 2.0;

/// The weight under which a structure is not named as a rival
/// (its share of the spread still counts).
pub const WEIGHT_FLOOR: f64 = 0.01;

/// The rig's spread among the structures (docs/methods.md, "The joint fit").
#[derive(Debug, Clone, PartialEq)]
pub struct StructureSpread {
    /// Each candidate's Schwarz (BIC) weight, in the candidates' order: 0
    /// for an unusable one.
    pub weights: Vec<f64>,
    /// The variance inflation the weights divide the costs by (docs/methods.md, "The joint fit").
    pub c_hat: f64,
    /// The structure std of beta1, a1b0, a2 and a3: sqrt of the weighted
    /// mean square of the candidates' differences from the chosen fit, less
    /// their statistical share (docs/methods.md, "The joint fit").
    pub std: [f64; 4],
    /// The structure covariance they come from.
    pub covariance: [[f64; 4]; 4],
    /// The structures of weight at least [`WEIGHT_FLOOR`] whose rig differs
    /// from the chosen one by more than the two fits' combined stds and
    /// [`HAUSMAN_Z`] statistical stds of the difference.
    pub rivals: Vec<Rival>,
}

/// A structure the data cannot tell from the chosen one.
#[derive(Debug, Clone, PartialEq)]
pub struct Rival {
    pub structure: Structure,
    pub weight: f64,
    pub moved: Vec<Moved>,
}

/// A rig parameter a rival puts elsewhere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Moved {
    /// 0-3: beta1, a1b0, a2, a3.
    pub parameter: usize,
    /// (rival - chosen) / chosen.
    pub relative: f64,
    /// (rival - chosen) over the two fits' combined std.
    pub z: f64,
}

/// Fit the structures to `runs` from the sequential estimate `start` and
/// choose among them. `opts` gives everything but the structure and the
/// starts; `band_top_hz` bounds a physical mode.
///
/// Where the friction is fitted, the seals' viscous damping c_v is tried
/// on the chosen structure, and where the data take it every structure is
/// fitted and chosen again with it. Tried on every structure from the
/// start, c_v takes over what the describing function leaves or a mode
/// explains (on simulated rigs with 20 N of friction and no damping it
/// came out 130 N s/m in the structures without the loop's mode, and they
/// were chosen); tried only on the structure the undamped choice made, a
/// rig that damps takes a mode for it first (docs/accuracy.md).
///
/// Then the logged command's gain ([`super::COMMAND_GAIN`]) is tried on
/// the chosen structure in the same way, and where the data take it every
/// structure is fitted and chosen again with it: a gain the rig does not
/// have is left at 1, so the fit is the paper's unless the logged command's
/// scale is shown to differ.
///
/// Last the servo-valve's flow-pressure law ([`super::FLOW_LAW`]) the same
/// way, where the runs' bins carry their amplitudes: its F_max where the
/// data take it, else the nameplate's where the manifest gives one, the
/// rig then the zero-load one.
pub fn select(
    runs: &[JointRun<'_>],
    start: &RigParams,
    opts: &JointOptions,
    choice: Choice,
    band_top_hz: f64,
) -> Selection {
    let undamped = select_among(runs, start, opts, choice, band_top_hz);
    let (selection, opts) = if opts.seal_damping || !seal_damping_taken(runs, &undamped, opts) {
        (undamped, *opts)
    } else {
        let damped = JointOptions {
            seal_damping: true,
            ..*opts
        };
        (
            select_among(runs, start, &damped, choice, band_top_hz),
            damped,
        )
    };
    let gain = if opts.command_gain {
        None
    } else {
        command_gain_taken(runs, &selection, &opts)
    };
    let (selection, opts) = match gain {
        Some(gain) => {
            let gained = JointOptions {
                command_gain: true,
                command_gain_start: gain,
                ..opts
            };
            (
                select_among(runs, start, &gained, choice, band_top_hz),
                gained,
            )
        }
        None => (selection, opts),
    };
    if opts.flow_law || !(opts.try_flow_law || opts.max_force_nameplate_n.is_some()) {
        return selection;
    }
    let loaded = match (
        flow_law_taken(runs, &selection, &opts),
        opts.max_force_nameplate_n,
    ) {
        (Some(max_force_n), _) => JointOptions {
            flow_law: true,
            max_force_start_n: max_force_n,
            ..opts
        },
        (None, Some(_)) => JointOptions {
            flow_law_held: true,
            ..opts
        },
        (None, None) => return selection,
    };
    select_among(runs, start, &loaded, choice, band_top_hz)
}

/// F_max (N) of the flow-pressure law, where the chosen fit refitted with
/// the law freed is taken ([`refit_taken`]) at an F_max the data determine
/// (its std below its value) beyond every force the runs reached. The
/// refit starts at the nameplate's F_max where the manifest gives it, else
/// at five times the largest force amplitude of any bin (|S| X), where the
/// law moves x1/u by some 8 %.
fn flow_law_taken(
    runs: &[JointRun<'_>],
    selection: &Selection,
    opts: &JointOptions,
) -> Option<f64> {
    let peak = peak_force_n(runs)?;
    let freed = JointOptions {
        flow_law: true,
        max_force_start_n: opts.max_force_nameplate_n.unwrap_or(5.0 * peak),
        ..*opts
    };
    let refit = refit_taken(runs, selection.fit()?, &freed)?;
    let fmax = refit.max_force_n?;
    let k = refit.names.iter().position(|n| *n == super::FLOW_LAW)?;
    (fmax > peak && refit.std[k] < fmax).then_some(fmax)
}

/// The largest force amplitude (N) the runs' bins carry, |S(jw)| X: None
/// where no run with a specimen has amplitudes.
fn peak_force_n(runs: &[JointRun<'_>]) -> Option<f64> {
    let mut peak = 0.0_f64;
    for run in runs.iter().filter(|r| r.bins.has_amplitudes()) {
        let bins = run.bins.all();
        let Some(x) = &bins.amplitude_m else { continue };
        let (m, c, k) = run.specimen.mck();
        for (&f, &x) in bins.freq_hz.iter().zip(x.iter()) {
            let w = 2.0 * std::f64::consts::PI * f;
            peak = peak.max(Complex::new(k - m * w * w, c * w).norm() * x);
        }
    }
    (peak > 0.0).then_some(peak)
}

/// The logged command's gain, where the chosen fit refitted with the gain
/// freed is taken ([`refit_taken`]).
fn command_gain_taken(
    runs: &[JointRun<'_>],
    selection: &Selection,
    opts: &JointOptions,
) -> Option<f64> {
    let freed = JointOptions {
        command_gain: true,
        command_gain_start: 1.0,
        ..*opts
    };
    refit_taken(runs, selection.fit()?, &freed)?.command_gain
}

/// Whether the chosen fit refitted with the seals' viscous damping freed
/// is taken ([`refit_taken`]) with a damping that does not drive the
/// piston. A fit without friction has none to free.
fn seal_damping_taken(runs: &[JointRun<'_>], selection: &Selection, opts: &JointOptions) -> bool {
    let Some(fit) = selection.fit().filter(|f| f.friction_n.is_some()) else {
        return false;
    };
    let freed = JointOptions {
        seal_damping: true,
        ..*opts
    };
    // The refit's other parameters may leave the physical range or stall
    // (a mode the damping makes redundant, its damping going to zero): that
    // is for the choice among the damped structures to settle; here only
    // the damping is judged. A refit stopped short of its optimum only
    // understates what the damping explains.
    refit_taken(runs, fit, &freed).is_some_and(|r| r.seal_damping_driving().is_none())
}

/// `fit` refitted from its optimum (its friction too) with what `freed`
/// frees, where the extra-sum-of-squares F test takes the refit over it
/// (p < [`P_SIGNIFICANT`]).
fn refit_taken(runs: &[JointRun<'_>], fit: &JointFit, freed: &JointOptions) -> Option<JointFit> {
    let opts = JointOptions {
        friction_start_n: fit.friction_n.unwrap_or(freed.friction_start_n),
        ..from_optimum(fit, freed)
    };
    let refit = joint_fit(runs, &fit.rig, &opts).ok()?;
    (f_test(fit, &refit).p_value < P_SIGNIFICANT).then_some(refit)
}

/// `opts` for a refit of `fit`'s structure started at its optimum: its
/// mode, piston mass and delays.
fn from_optimum(fit: &JointFit, opts: &JointOptions) -> JointOptions {
    JointOptions {
        structure: fit.structure,
        valve_start: fit.mode.unwrap_or(opts.valve_start),
        piston_start_kg: fit.piston_mass_kg.unwrap_or(opts.piston_start_kg),
        delay_start_s: fit.delay_s,
        force_delay_start_s: fit.force_delay_s.unwrap_or(fit.delay_s),
        ..*opts
    }
}

/// `fit`'s structure and extras (friction, seal damping, command gain,
/// flow law) fitted again to other bins of the same runs, from `fit`'s
/// optimum: the fit a simulation of the fitted rig gets, whose departure
/// from the rig simulated is the estimator's bias there.
pub fn refit(
    runs: &[JointRun<'_>],
    fit: &JointFit,
    opts: &JointOptions,
) -> Result<JointFit, FitError> {
    let law = fit.names.contains(&super::FLOW_LAW);
    let o = JointOptions {
        friction: fit.friction_n.is_some(),
        friction_start_n: fit.friction_n.unwrap_or(0.0),
        seal_damping: fit.seal_damping_ns_per_m.is_some(),
        command_gain: fit.command_gain.is_some(),
        command_gain_start: fit.command_gain.unwrap_or(1.0),
        flow_law: law,
        max_force_start_n: if law {
            fit.max_force_n.unwrap_or(f64::INFINITY)
        } else {
            opts.max_force_start_n
        },
        flow_law_held: !law && fit.max_force_n.is_some(),
        ..from_optimum(fit, opts)
    };
    joint_fit(runs, &fit.rig, &o)
}

/// [`select`] with the seals' viscous damping as `opts` says.
fn select_among(
    runs: &[JointRun<'_>],
    start: &RigParams,
    opts: &JointOptions,
    choice: Choice,
    band_top_hz: f64,
) -> Selection {
    let mut candidates = fit_candidates(runs, start, opts, choice, band_top_hz);
    flag_local_optima(&mut candidates);
    let base = choose_nested(&mut candidates);
    let auto = choose_mode(&mut candidates, base).or(base);
    let auto = auto.map(|i| candidates[i].structure);
    let chosen = match choice {
        Choice::Auto => auto,
        Choice::Fixed(s) => candidates
            .iter()
            .find(|c| c.structure == s && c.fit.is_ok())
            .map(|c| c.structure),
    };
    Selection {
        candidates,
        auto,
        chosen,
        choice,
    }
}

/// `fit` as a candidate, with why it is unusable although it ran.
fn assess(
    structure: Structure,
    fit: Result<JointFit, FitError>,
    band_top_hz: f64,
    max_delay_s: f64,
) -> Candidate {
    let unusable = match &fit {
        Err(_) => None,
        Ok(f) if !f.converged => Some(format!(
            "Levenberg-Marquardt stopped after {} iterations without converging",
            f.iterations
        )),
        Ok(f) => f.unphysical(band_top_hz, max_delay_s),
    };
    Candidate {
        structure,
        fit,
        unusable,
        f_test: None,
    }
}

/// The most bins of independent fits over the same runs that are fitted
/// side by side. Each fit holds its own problem, about 20 bytes a bin
/// besides the FRFs it reads: below this it is small beside the logs in
/// flight, and the fits' sequential stretches overlap (one at a time, the
/// 300-log night's rig took 15 % longer); above it one problem at a time
/// bounds the rig's memory (a 3,000-log night's 601 FRFs hold 2.1 M bins,
/// 42 MB a problem, and six candidates side by side would take 0.25 GB).
const SIDE_BY_SIDE_MAX_BINS: usize = 500_000;

/// Whether independent fits over `runs` go side by side.
fn side_by_side(runs: &[JointRun<'_>]) -> bool {
    runs.iter().map(|r| r.bins.len()).sum::<usize>() <= SIDE_BY_SIDE_MAX_BINS
}

/// Every candidate's fit, in the order the choice reads them: the paper's
/// model, the delay, then the piston and each place of a mode.
fn fit_candidates(
    runs: &[JointRun<'_>],
    start: &RigParams,
    opts: &JointOptions,
    choice: Choice,
    band_top_hz: f64,
) -> Vec<Candidate> {
    let assess = |structure, fit| assess(structure, fit, band_top_hz, opts.max_delay_s);
    let with = |structure: Structure| JointOptions {
        structure,
        delay_start_s: 0.0,
        force_delay_start_s: 0.0,
        ..*opts
    };
    // The two smaller structures are independent fits: side by side where
    // they are small (each is the same computation on any thread count).
    let together = side_by_side(runs);
    let staged = |s: Structure| assess(s, joint_fit_staged(runs, start, &with(s), GRID_STRIDE));
    let (plain, delay) = match together {
        true => rayon::join(|| staged(Structure::Plain), || staged(Structure::Delay)),
        false => (staged(Structure::Plain), staged(Structure::Delay)),
    };
    // The measurement path differs from the command path only on force
    // FRFs: without them the two are one model, fitted once.
    let has_force = runs.iter().any(|r| r.output == Output::Force);
    let mut places = vec![
        Structure::DelayPiston,
        Structure::DelayValve,
        Structure::DelayCommand,
    ];
    if has_force || choice == Choice::Fixed(Structure::DelayMeasurement) {
        places.push(Structure::DelayMeasurement);
    }
    // The extensions are independent fits from the delay fit: side by side
    // (each the same computation on any thread count, collected in order),
    // so one's sequential stretches (the solver's steps, the adequacy
    // pass) overlap another's parallel passes.
    let extensions: Vec<Candidate> = {
        let delay_fit = delay.usable();
        let fit = |&place: &Structure| {
            assess(
                place,
                fit_mode(runs, start, delay_fit, opts, band_top_hz, place),
            )
        };
        match together {
            true => places.par_iter().with_max_len(1).map(fit).collect(),
            false => places.iter().map(fit).collect(),
        }
    };
    let usable = |s: Structure| {
        extensions
            .iter()
            .find(|c| c.structure == s)
            .and_then(|c| c.usable())
    };
    // The loop's mode with the piston's mass is tried where the data take
    // each alone over the delay (or the manifest names it): a rig with
    // both shows each, and a rig with neither need not pay for the fit.
    let taken = |s: Structure| match (delay.usable(), usable(s)) {
        (Some(small), Some(big)) => f_test(small, big).p_value < P_SIGNIFICANT,
        _ => false,
    };
    let try_both = choice == Choice::Fixed(Structure::DelayValvePiston)
        || (taken(Structure::DelayValve) && taken(Structure::DelayPiston));
    let both = try_both.then(|| {
        assess(
            Structure::DelayValvePiston,
            fit_valve_piston(
                runs,
                usable(Structure::DelayValve),
                usable(Structure::DelayPiston),
                opts,
            ),
        )
    });
    let mut candidates = vec![plain, delay];
    candidates.extend(extensions);
    candidates.extend(both);
    candidates
}

/// The servo-valve's mode and the piston's mass together, from the fits
/// that hold each alone: the valve fit's optimum with the piston fit's
/// mass (or the piston's default start).
fn fit_valve_piston(
    runs: &[JointRun<'_>],
    valve: Option<&JointFit>,
    piston: Option<&JointFit>,
    opts: &JointOptions,
) -> Result<JointFit, FitError> {
    let valve = valve.ok_or(FitError::NoSolution)?;
    let both = JointOptions {
        structure: Structure::DelayValvePiston,
        valve_start: valve.mode.ok_or(FitError::NoSolution)?,
        piston_start_kg: piston
            .and_then(|p| p.piston_mass_kg)
            .unwrap_or(opts.piston_start_kg),
        delay_start_s: valve.delay_s,
        force_delay_start_s: valve.force_delay_s.unwrap_or(valve.delay_s),
        friction_start_n: valve.friction_n.unwrap_or(opts.friction_start_n),
        command_gain_start: valve.command_gain.unwrap_or(opts.command_gain_start),
        max_force_start_n: valve.max_force_n.unwrap_or(opts.max_force_start_n),
        ..*opts
    };
    joint_fit_staged(runs, &valve.rig, &both, GRID_STRIDE)
}

/// Mark unusable each larger structure that stopped above the cost of a
/// structure it holds.
///
/// Every larger structure holds the paper's model and the delay (module
/// docs), and the loop's mode with the piston's mass holds each alone, so
/// at its optimum it fits at least as well as they do; one that stopped
/// above the cost of a structure it holds stopped at a local optimum, and
/// its rig is not that structure's answer.
pub(super) fn flag_local_optima(candidates: &mut [Candidate]) {
    for i in 1..candidates.len() {
        let holds = |c: &Candidate| match candidates[i].structure {
            Structure::DelayValvePiston => matches!(
                c.structure,
                Structure::Plain
                    | Structure::Delay
                    | Structure::DelayValve
                    | Structure::DelayPiston
            ),
            _ => false,
        };
        let nested_best = candidates[..i]
            .iter()
            .enumerate()
            .filter(|&(j, c)| j < 2 || holds(c))
            .filter_map(|(_, c)| c.usable().map(|f| (c.structure, f.cost)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let above = match (candidates[i].usable(), nested_best) {
            (Some(f), Some((s, cost))) => {
                (f.cost > cost * (1.0 + 1e-9)).then_some((s, cost, f.cost))
            }
            _ => None,
        };
        if let Some((s, cost, own)) = above {
            candidates[i].unusable = Some(format!(
                "stopped at a local optimum: its cost {own:.6e} is above that of the {s:?} structure it holds ({cost:.6e})"
            ));
        }
    }
}

/// The index of the paper's model or the delay, whichever the F test
/// takes: forward through the nested chain, the delay against the paper's
/// model. None when neither is usable.
fn choose_nested(candidates: &mut [Candidate]) -> Option<usize> {
    let mut auto: Option<usize> = None;
    for i in 0..2 {
        if candidates[i].usable().is_none() {
            continue;
        }
        let Some(a) = auto else {
            auto = Some(i);
            continue;
        };
        let test = f_test(
            candidates[a].usable().expect("usable"),
            candidates[i].usable().expect("usable"),
        );
        candidates[i].f_test = Some(test);
        if test.p_value < P_SIGNIFICANT {
            auto = Some(i);
        }
    }
    auto
}

/// The index of the mode or piston taken over `base` (the nested chain's
/// choice) by the F test, the lowest AIC among those taken; None when the
/// test takes none.
fn choose_mode(candidates: &mut [Candidate], base: Option<usize>) -> Option<usize> {
    let mut best_mode: Option<usize> = None;
    for i in 2..candidates.len() {
        // Akaike's criterion with the noise known: the cost plus twice the
        // parameter count (with equal counts, the lower cost).
        let Some(aic) = candidates[i]
            .usable()
            .map(|f| f.cost + 2.0 * f.params.len() as f64)
        else {
            continue;
        };
        // The valve-and-piston fit is tested against whichever of the two it
        // holds fits better.
        let against = if candidates[i].structure == Structure::DelayValvePiston {
            nested_extension(candidates).or(base)
        } else {
            base
        };
        let taken = match against {
            Some(a) => {
                let test = f_test(
                    candidates[a].usable().expect("usable"),
                    candidates[i].usable().expect("usable"),
                );
                candidates[i].f_test = Some(test);
                test.p_value < P_SIGNIFICANT
            }
            None => true,
        };
        let lower = best_mode
            .and_then(|b| candidates[b].usable())
            .is_none_or(|b| aic < b.cost + 2.0 * b.params.len() as f64);
        if taken && lower {
            best_mode = Some(i);
        }
    }
    best_mode
}

/// The index of the usable valve or piston fit with the lower cost.
fn nested_extension(candidates: &[Candidate]) -> Option<usize> {
    candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| matches!(c.structure, Structure::DelayValve | Structure::DelayPiston))
        .filter_map(|(i, c)| c.usable().map(|f| (i, f.cost)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// The extra-sum-of-squares F test of `big` against the nested `small`.
fn f_test(small: &JointFit, big: &JointFit) -> FTest {
    let dp = (big.params.len() - small.params.len()) as f64;
    let scale = big.cost / big.dof as f64;
    let f = ((small.cost - big.cost) / dp / scale).max(0.0);
    let p_value = FisherSnedecor::new(dp, big.dof as f64)
        .map(|d| d.sf(f))
        .unwrap_or(f64::NAN);
    FTest {
        against: small.structure,
        f,
        p_value,
    }
}

/// Iterations each of the two best valve-mode starts is given before only
/// the one with the lower cost is followed on. On the seven-run bench both
/// reach the same optimum (in 12 and 9 iterations); racing them three
/// iterations rather than running both to the end takes a third fewer
/// passes over the bins. Checked over the 2,008 valve fits `tests/joint.rs`
/// makes (rich and clean campaigns, the coverage seeds): wherever the two
/// starts, each run to the end, reach optima that differ, the race picked
/// the start of the lower one, but once, where neither converged (a clean
/// campaign, whose data have no valve mode to find). The
/// race and the leg after it run on the grid's quarter of the bins, and
/// only the last leg on every bin; the rule is the same for each place.
const RACE_ITERATIONS: u64 = 3;

/// The valve-mode grid is scored on every this many bins of each run: the
/// score only ranks the starts, and a quarter of the bins rank them as all
/// do (the same two best starts in every one of the 2,008 valve fits of
/// `tests/joint.rs`).
const GRID_STRIDE: usize = 4;

/// A point of the mode's (or the piston's) grid of starts and the cost
/// there.
struct ValveStart {
    cost: f64,
    hz: f64,
    zeta: f64,
    piston_kg: f64,
    delay_s: f64,
    force_delay_s: f64,
}

/// The delay-and-mode (or delay-and-piston) fit of `structure` from the
/// best starts of a grid (docs/methods.md, "The joint fit").
fn fit_mode(
    runs: &[JointRun<'_>],
    start: &RigParams,
    delay_fit: Option<&JointFit>,
    opts: &JointOptions,
    band_top_hz: f64,
    structure: Structure,
) -> Result<JointFit, FitError> {
    // The friction, when fitted, starts where the delay fit put it.
    let friction_start_n = delay_fit.and_then(|f| f.friction_n).unwrap_or(0.0);
    let seal_damping_start = delay_fit
        .and_then(|f| f.seal_damping_ns_per_m)
        .unwrap_or(0.0);
    let command_gain_start = delay_fit
        .and_then(|f| f.command_gain)
        .unwrap_or(opts.command_gain_start);
    let max_force_start_n = delay_fit
        .and_then(|f| f.max_force_n)
        .unwrap_or(opts.max_force_start_n);
    let base = JointOptions {
        structure,
        friction_start_n,
        ..*opts
    };
    let (rig, delay_s, force_delay_s) = match delay_fit {
        Some(f) => (f.rig, f.delay_s, f.force_delay_s.unwrap_or(f.delay_s)),
        None => (*start, 0.0, 0.0),
    };
    let mut prob = problem(runs, &base)?;
    let mut coarse = prob.every(GRID_STRIDE);
    // The grid is scored, and the race run, with the aliases of the delay
    // fit's model (the last leg follows its own).
    coarse.follow_aliases(
        &Point::of_rig(&rig, opts.p_ref, delay_s, force_delay_s),
        1.0,
    );
    let with_force = coarse.force_delay.is_some();
    let mut grid = Vec::new();
    if structure.piston() {
        grid.extend(piston_starts(
            &rig,
            delay_s,
            force_delay_s,
            opts,
            band_top_hz,
            with_force,
        ));
    }
    if structure.place().is_some() {
        grid.extend(mode_starts(
            &rig,
            delay_s,
            force_delay_s,
            opts,
            band_top_hz,
            structure,
            with_force,
        ));
    }
    if coarse.friction.is_some() {
        for (theta, _) in &mut grid {
            theta.push(friction_start_n);
        }
    }
    if coarse.seal_damping.is_some() {
        for (theta, _) in &mut grid {
            theta.push(seal_damping_start);
        }
    }
    if coarse.command_gain.is_some() {
        for (theta, _) in &mut grid {
            theta.push(command_gain_start.ln());
        }
    }
    if coarse.flow_law.is_some() {
        for (theta, _) in &mut grid {
            theta.push(-max_force_start_n.ln());
        }
    }
    let mut scored: Vec<ValveStart> = grid
        .into_iter()
        .filter_map(|(theta, start)| {
            let cost = coarse.cost(&theta);
            cost.is_finite().then_some(ValveStart { cost, ..start })
        })
        .collect();
    scored.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    race(&mut prob, &coarse, &rig, &base, &scored)
}

/// The piston's starts: its mode over the same range as a mode's,
/// sqrt(a2 / m_p) from 1.5 to 12 times the band's top; the delays as the
/// delay fit has them. Each with its theta, the cost not yet scored.
fn piston_starts(
    rig: &RigParams,
    delay_s: f64,
    force_delay_s: f64,
    opts: &JointOptions,
    band_top_hz: f64,
    with_force: bool,
) -> Vec<(Vec<f64>, ValveStart)> {
    let fs = opts.sample_rate_hz;
    let rig_theta = rig_theta(rig, opts.p_ref);
    (0..6)
        .map(|i| {
            let w = 2.0 * std::f64::consts::PI * 1.5 * band_top_hz * 8f64.powf(i as f64 / 5.0);
            let mp = rig.a2_n_per_m / (w * w);
            let mut theta = rig_theta.to_vec();
            theta.extend([delay_s * fs, mp.ln()]);
            if with_force {
                theta.push(force_delay_s * fs);
            }
            let start = ValveStart {
                cost: 0.0,
                hz: 0.0,
                zeta: 0.0,
                piston_kg: mp,
                delay_s,
                force_delay_s,
            };
            (theta, start)
        })
        .collect()
}

/// A mode's starts at `structure`'s place: frequencies from 1.5 to 12
/// times the band's top, dampings 0.3, 0.55 and 0.8, the delays less the
/// mode's lag. Each with its theta, the cost not yet scored.
fn mode_starts(
    rig: &RigParams,
    delay_s: f64,
    force_delay_s: f64,
    opts: &JointOptions,
    band_top_hz: f64,
    structure: Structure,
    with_force: bool,
) -> Vec<(Vec<f64>, ValveStart)> {
    let fs = opts.sample_rate_hz;
    let rig_theta = rig_theta(rig, opts.p_ref);
    let mut starts = Vec::new();
    for i in 0..6 {
        let hz = 1.5 * band_top_hz * 8f64.powf(i as f64 / 5.0);
        for zeta in [0.3, 0.55, 0.8] {
            let w = 2.0 * std::f64::consts::PI * hz;
            // The mode's low-frequency lag, 2 zeta / w, comes out of the
            // delays (the force's too: it is downstream of the valve).
            let lag = |d: f64| (d - 2.0 * zeta / w).clamp(0.0, opts.max_delay_s);
            // (A mode on the displacement channel leaves the force's.)
            let d_force = if structure == Structure::DelayMeasurement {
                force_delay_s
            } else {
                lag(force_delay_s)
            };
            let d = lag(delay_s);
            let mut theta = rig_theta.to_vec();
            theta.extend([d * fs, w.ln(), zeta.ln()]);
            if with_force {
                theta.push(d_force * fs);
            }
            let start = ValveStart {
                cost: 0.0,
                hz,
                zeta,
                piston_kg: 0.0,
                delay_s: d,
                force_delay_s: d_force,
            };
            starts.push((theta, start));
        }
    }
    starts
}

/// The fit from the best of the `scored` starts (sorted by cost), raced on
/// `coarse` and finished on every bin of `prob`.
///
/// Levenberg-Marquardt from the two best starts side by side, on the
/// quarter of the bins the grid was scored on, for a few iterations; then
/// only the one with the lower cost (the first on a tie) goes on to that
/// problem's optimum, and from there on every bin to the optimum of all of
/// them (its aliases its own), which alone is finished (covariance,
/// adequacy). The quarter's
/// optimum is within its noise of the whole's, so the last leg takes a few
/// iterations where a start from the grid takes a dozen.
fn race(
    prob: &mut JointProblem,
    coarse: &JointProblem,
    rig: &RigParams,
    base: &JointOptions,
    scored: &[ValveStart],
) -> Result<JointFit, FitError> {
    let options = |v: &ValveStart| JointOptions {
        valve_start: (v.hz, v.zeta),
        piston_start_kg: v.piston_kg,
        delay_start_s: v.delay_s,
        force_delay_start_s: v.force_delay_s,
        ..*base
    };
    let race = RACE_ITERATIONS.min(base.max_iterations);
    let leg = |v: &ValveStart| Leg::from(coarse, rig, &options(v), race);
    let (start, leg) = match scored {
        [] => return Err(FitError::NoSolution),
        [one] => (one, leg(one)),
        [a, b, ..] => match rayon::join(|| leg(a), || leg(b)) {
            (Ok(x), Ok(y)) if y.optimum.cost < x.optimum.cost => (b, Ok(y)),
            (Err(_), Ok(y)) => (b, Ok(y)),
            (x, _) => (a, x),
        },
    };
    let leg = leg?;
    let more = base.max_iterations.saturating_sub(leg.optimum.iterations);
    let near = leg.go_on(coarse, more)?.optimum.theta;
    let full = options(start);
    let optimum = settle(prob, &full, near)?;
    finish(prob, optimum, &full)
}

/// The rig's spread over the runs, for a fit its adequacy tests reject.
///
/// When no candidate holds what the rig has (friction, two modes at once)
/// the chosen fit is a compromise, and each run pulls it its own way: a
/// friction force weighs on the no-specimen run and hardly on a stiff
/// spring's. The delete-one jackknife over the FRFs (Efron & Tibshirani
/// 1993, An Introduction to the Bootstrap, Ch. 11) measures that pull:
/// var_jack = (n - 1)/n sum (theta_(i) - theta_(.))^2, each theta_(i) the
/// chosen structure refitted without FRF i from the chosen optimum. Under
/// the right model it estimates the statistical variance; what it holds
/// beyond that, var_jack - var_stat floored at 0, is the model-error
/// variance this returns (per rig parameter), with the number of refits.
/// Past `JACKKNIFE_GROUPS` FRFs (a night's dozens of springs) the FRFs
/// are dealt into that many groups (FRF i to group i mod G) and each refit
/// leaves a group out: the delete-a-group jackknife, var = (G - 1)/G sum
/// (theta_(g) - theta_(.))^2 (Kott 2001, "The delete-a-group jackknife",
/// J. Official Statistics 17(4):521-526), G refits where one per FRF made
/// its cost grow as the square of the FRFs.
/// None for an adequate fit, a single FRF, or when a refit fails (an FRF
/// alone carries a parameter: the rig cannot be had without it).
#[derive(Debug, Clone, PartialEq)]
pub struct RunSpread {
    /// Model-error std of beta1, a1b0, a2 and a3.
    pub std: [f64; 4],
    /// The jackknife's own std of each, statistical share included.
    pub jackknife_std: [f64; 4],
    pub refits: usize,
    /// The FRFs the refits left out, one or a group at a time.
    pub frfs: usize,
}

/// The most refits [`run_spread`]'s jackknife makes.
pub const JACKKNIFE_GROUPS: usize = 20;

/// A campaign's joint fit: the structure chosen, on which runs, and the
/// runs' model-error spread where the chosen fit misses.
#[derive(Debug)]
pub struct JointIdentification<'a> {
    /// The runs the structure was chosen on: as given, or with every
    /// spring's cubic term dropped where the data take the stated k.
    pub runs: Vec<JointRun<'a>>,
    pub selection: Selection,
    /// [`run_spread`] of the chosen fit.
    pub misfit: Option<RunSpread>,
    /// Whether some spring's cubic term, read from its force, was given
    /// and the fit holds at least as well with each stated k.
    pub stiffening_rejected: bool,
}

impl JointIdentification<'_> {
    /// The total covariance of the chosen rig's beta1, a1b0, a2 and a3:
    /// the fit's own, the spread among the structures
    /// ([`Selection::spread`]) and the runs' model-error spread on the
    /// diagonal (the jackknife's correlations are too few refits to
    /// trust). None when no structure is chosen.
    pub fn rig_covariance(&self) -> Option<[[f64; 4]; 4]> {
        let fit = self.selection.fit()?;
        let structure = self
            .selection
            .spread()
            .map_or([[0.0; 4]; 4], |s| s.covariance);
        let misfit: [f64; 4] = self
            .misfit
            .as_ref()
            .map_or([0.0; 4], |m| m.std.map(|s| s * s));
        Some(std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                fit.covariance[(i, j)] + structure[i][j] + if i == j { misfit[i] } else { 0.0 }
            })
        }))
    }

    /// R1 = a1b0 / a2 of the chosen rig, with its first-order std from
    /// [`Self::rig_covariance`].
    pub fn r1(&self) -> Option<Estimate> {
        let (rig, cov) = (&self.selection.fit()?.rig, self.rig_covariance()?);
        let (a, b) = (rig.a1b0_n_per_m_s2, rig.a2_n_per_m);
        // Gradient (1 / a2, -a1b0 / a2^2) over (a1b0, a2).
        let g = [1.0 / b, -a / (b * b)];
        let var = g[0] * g[0] * cov[1][1] + 2.0 * g[0] * g[1] * cov[1][2] + g[1] * g[1] * cov[2][2];
        Some(Estimate {
            value: rig.r1(),
            std: Some(var.max(0.0).sqrt()),
        })
    }
}

/// The joint fit of a campaign's `runs` from the sequential rig `start`
/// (docs/methods.md, "The joint fit"): the structure chosen by [`select`];
/// where a spring's stiffening was read from its force, chosen again with
/// each stated k and the better of the two kept by Schwarz's criterion (a
/// load cell's delay against the LVDT's can mimic a cubic term); then the
/// runs' spread about the chosen fit ([`run_spread`]).
pub fn identify<'a>(
    runs: Vec<JointRun<'a>>,
    start: &RigParams,
    opts: &JointOptions,
    choice: Choice,
    band_top_hz: f64,
) -> JointIdentification<'a> {
    let sel = select(&runs, start, opts, choice, band_top_hz);
    let (runs, selection, stiffening_rejected) =
        if runs.iter().any(|r| r.spring_cubic_n_per_m3.is_some()) {
            let stated: Vec<JointRun<'_>> = runs
                .iter()
                .map(|r| JointRun {
                    spring_cubic_n_per_m3: None,
                    ..*r
                })
                .collect();
            let linear = select(&stated, start, opts, choice, band_top_hz);
            let bic = |s: &Selection| s.chosen.and_then(|c| s.candidate(c)?.bic());
            match (bic(&sel), bic(&linear)) {
                (Some(with), Some(without)) if without <= with => (stated, linear, true),
                (None, Some(_)) => (stated, linear, false),
                _ => (runs, sel, false),
            }
        } else {
            (runs, sel, false)
        };
    let misfit = run_spread(&runs, &selection, opts);
    JointIdentification {
        runs,
        selection,
        misfit,
        stiffening_rejected,
    }
}

/// [`RunSpread`] of the chosen fit of `sel` over `runs`.
pub fn run_spread(
    runs: &[JointRun<'_>],
    sel: &Selection,
    opts: &JointOptions,
) -> Option<RunSpread> {
    let fit = sel.fit()?;
    if fit.adequacy.passed() || runs.len() < 2 {
        return None;
    }
    let from = from_optimum(fit, opts);
    let groups = runs.len().min(JACKKNIFE_GROUPS);
    // A refit per group (each a joint fit to its optimum), side by side where they
    // are small, gathered in group order: the same bits on any number of
    // threads.
    let refit = |g: usize| {
        let rest: Vec<JointRun<'_>> = runs
            .iter()
            .enumerate()
            .filter(|(j, _)| j % groups != g)
            .map(|(_, r)| *r)
            .collect();
        let (params, converged) = joint_fit_params(&rest, &fit.rig, &from).ok()?;
        converged.then(|| std::array::from_fn(|k| params[k]))
    };
    let refits: Vec<Option<[f64; 4]>> = match side_by_side(runs) {
        true => (0..groups)
            .into_par_iter()
            .with_max_len(1)
            .map(refit)
            .collect(),
        false => (0..groups).map(refit).collect(),
    };
    let refits: Vec<[f64; 4]> = refits.into_iter().collect::<Option<_>>()?;
    let n = refits.len() as f64;
    let mut jackknife_std = [0.0; 4];
    let mut std = [0.0; 4];
    for k in 0..4 {
        let mean = refits.iter().map(|t| t[k]).sum::<f64>() / n;
        let var = (n - 1.0) / n * refits.iter().map(|t| (t[k] - mean).powi(2)).sum::<f64>();
        jackknife_std[k] = var.sqrt();
        std[k] = (var - fit.std[k].powi(2)).max(0.0).sqrt();
    }
    Some(RunSpread {
        std,
        jackknife_std,
        refits: refits.len(),
        frfs: runs.len(),
    })
}
