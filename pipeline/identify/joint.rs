//! The joint grey-box estimator of the rig: beta1, a1b0 (at a reference P
//! gain), a2 and a3 fitted together to the FRFs of several runs, each
//! run's model the exact x1/u (or f/u) of its specimen at its P gain
//! (Eqs. 12, 14, 17 and 45), with what every run shares: the command's
//! hold and its aliases, a delay, optionally a second-order mode in the
//! loop, the command path or the measurement path, the piston's mass, its
//! seals' friction and damping, and the logged command's gain.
//!
//! In the notation below, Q = (s + a3) S + a2 s, A = a1b0 P / P_ref, V the
//! mode's factor, and x1/u = A V / D with D = (s + beta1) Q + A V in the
//! loop (D0 = (s + beta1) Q + A outside it). Parameters are solved for as
//! logarithms, the delay in samples, by Levenberg-Marquardt on J^T J and
//! J^T r summed bin by bin (`Normal`). The model's derivation and the
//! solver's choices: docs/methods.md, "The joint fit".

use argmin::core::{Error as ArgminError, Executor, Jacobian, State, TerminationReason};
use nalgebra::{Complex, DMatrix, DVector};

use crate::fit::Intersample;
use crate::fit::adequacy::{Adequacy, Residuals, Sums};
use crate::fit::lm::{LevenbergMarquardt, Normal};
use crate::fit::problem::{alias_factor, hold_response};
use crate::fit::{FitError, covariance_from_normal, covariance_streamed};
use crate::identify::FitData;
use crate::identify::bins::{Bins, Span};
use crate::lti::TransferFunction;
use crate::model::{self, LinearSpecimen, RigParams};
use crate::poly;
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// What a run's FRF measures over the command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// The displacement x1 (Eqs. 12, 14, 17).
    Displacement,
    /// The force f on the specimen, S(s) x1 (Eq. 45).
    Force,
}

/// One run's measured FRF, x1/u or f/u, and what the manifest says of it.
#[derive(Debug, Clone, Copy)]
pub struct JointRun<'a> {
    pub specimen: LinearSpecimen,
    pub p_gain: f64,
    pub output: Output,
    /// Its bins: frequency, H, E|dH|^2 and, from a sweep
    /// (`frf::sweep_amplitude`) where the run's seal friction is fitted, the
    /// displacement's amplitude (m), on which the friction's describing
    /// function depends.
    pub bins: Bins<'a>,
    /// The FRF's grid spacing (Hz): the residual correlation test pairs
    /// bins on it.
    pub bin_hz: f64,
    /// The lag (bins) from which its errors are independent: the FRF
    /// estimator's kernel (`frf::FrfPlan::independent_lag`). The residual
    /// correlation test pairs its bins this far apart, and bins closer
    /// share data in the sandwich covariance.
    pub lag: usize,
    /// A spring that stiffens, its cubic term k3 (N/m^3) from its force
    /// against its displacement: at each bin its describing function
    /// k + 3/4 k3 X^2 at the bin's amplitude X stands for its k (where the
    /// run has amplitudes).
    pub spring_cubic_n_per_m3: Option<f64>,
}

/// The joint fit's nuisance dynamics besides the command's hold: as the
/// manifest fixes it (`identification.joint.structure`) and as the results
/// name the one used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
#[schemars(rename = "JointStructure")]
pub enum Structure {
    /// The paper's model alone.
    #[serde(rename = "none")]
    Plain,
    /// And a pure delay.
    Delay,
    /// And a delay and a second-order mode in the position loop (the
    /// servo-valve spool's).
    DelayValve,
    /// And a delay and a second-order mode in the command path, ahead of
    /// the loop (a command filter or valve driver): displacement and force
    /// follow it.
    DelayCommand,
    /// And a delay and a second-order mode in the displacement's
    /// measurement path (a sensor or logging filter outside the loop): the
    /// force does not follow it.
    DelayMeasurement,
    /// And a delay and the piston's mass on the oil column (the actuator's
    /// own mode): Q = (s + a3)(S + m_p s^2) + a2 s.
    DelayPiston,
    /// And a delay, the servo-valve's mode in the loop and the piston's
    /// mass: a rig with both.
    DelayValvePiston,
}

/// Where a structure's second-order mode sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// Inside the position loop: its effect on x1/u changes with the loop
    /// gain, hence with the P gain and the specimen.
    Loop,
    /// In the command path: a factor on x1/u and f/u alike, whatever the
    /// loop does.
    Command,
    /// In the displacement's measurement path: a factor on x1/u only.
    Measurement,
}

impl Structure {
    pub const ALL: [Structure; 7] = [
        Structure::Plain,
        Structure::Delay,
        Structure::DelayValve,
        Structure::DelayCommand,
        Structure::DelayMeasurement,
        Structure::DelayPiston,
        Structure::DelayValvePiston,
    ];

    /// As the manifest and results.json spell it (serde's names above).
    pub const fn as_str(self) -> &'static str {
        match self {
            Structure::Plain => "none",
            Structure::Delay => "delay",
            Structure::DelayValve => "delay_valve",
            Structure::DelayCommand => "delay_command",
            Structure::DelayMeasurement => "delay_measurement",
            Structure::DelayPiston => "delay_piston",
            Structure::DelayValvePiston => "delay_valve_piston",
        }
    }

    fn n_params(self) -> usize {
        match self {
            Structure::Plain => 4,
            Structure::Delay => 5,
            Structure::DelayPiston => 6,
            Structure::DelayValvePiston => 8,
            _ => 7,
        }
    }

    /// Whether it fits the piston's mass.
    pub fn piston(self) -> bool {
        matches!(self, Structure::DelayPiston | Structure::DelayValvePiston)
    }

    /// The piston mass's index among the parameters (after the mode's).
    fn piston_index(self) -> usize {
        if self.place().is_some() { 7 } else { 5 }
    }

    /// Where its mode sits, when it has one.
    pub fn place(self) -> Option<Place> {
        match self {
            Structure::Plain | Structure::Delay | Structure::DelayPiston => None,
            Structure::DelayValve | Structure::DelayValvePiston => Some(Place::Loop),
            Structure::DelayCommand => Some(Place::Command),
            Structure::DelayMeasurement => Some(Place::Measurement),
        }
    }

    /// The parameters' names, in the order of [`JointFit::params`] (which
    /// adds [`FORCE_DELAY`] last when force FRFs are fitted): the mode in
    /// the loop is the servo-valve's; outside it the mode's own.
    pub fn names(self) -> &'static [&'static str] {
        // The rig's four, the delay, the loop's mode and the piston: each
        // structure in the loop's line takes a prefix.
        const VALVE_PISTON: [&str; 8] = [
            "beta1_per_s",
            "a1b0_n_per_m_s2",
            "a2_n_per_m",
            "a3_per_s",
            "delay_s",
            "valve_hz",
            "valve_damping",
            "piston_mass_kg",
        ];
        match self {
            Structure::Plain => &VALVE_PISTON[..4],
            Structure::Delay => &VALVE_PISTON[..5],
            Structure::DelayPiston => &[
                "beta1_per_s",
                "a1b0_n_per_m_s2",
                "a2_n_per_m",
                "a3_per_s",
                "delay_s",
                "piston_mass_kg",
            ],
            Structure::DelayValve => &VALVE_PISTON[..7],
            Structure::DelayValvePiston => &VALVE_PISTON,
            Structure::DelayCommand | Structure::DelayMeasurement => &[
                "beta1_per_s",
                "a1b0_n_per_m_s2",
                "a2_n_per_m",
                "a3_per_s",
                "delay_s",
                "mode_hz",
                "mode_damping",
            ],
        }
    }
}

/// The name of the force FRFs' own delay, the last parameter of a
/// structure with a delay when any run's force over command is fitted: the
/// load cell's delay is its own, not the LVDT's (a sensor delay belongs to
/// its sensor; a delay in the command path shows as the two alike).
pub const FORCE_DELAY: &str = "force_delay_s";

/// The name of the piston's Coulomb seal friction (N), the last parameter
/// when it is fitted. On a slow sweep friction F sign(x1') acts at each
/// frequency as its describing function, a damper 4 F / (pi V) at the
/// velocity amplitude V the sweep drove there (V = w X, X the
/// displacement's amplitude), which adds 4 F / (pi X) j to the piston's
/// load S(s) in Q = (s + a3) S + a2 s: linear in F. The load cell, on the
/// rod's side of the seals, does not read it.
pub const FRICTION: &str = "coulomb_friction_n";

/// The name of the seals' viscous damping (N s/m), fitted after the
/// friction when the data take it: a force c_v x1' on the piston beside
/// F sign(x1'), which adds c_v s to the piston's load S(s), like a
/// specimen's damping shared by every run.
pub const SEAL_DAMPING: &str = "seal_damping_ns_per_m";

/// The name of the gain between the logged command and the command the
/// loop follows, the last parameter when it is fitted. Under P control the
/// piston integrates the valve's flow, so at rest the displacement equals
/// the command the loop sees (Eq. 12 at s = 0): the rig's own static gain
/// is 1 and no rig parameter can stand for another. The logged command
/// need not be that command: a reading of it through another converter or
/// calibration differs by a gain, and on a command of few levels (a square
/// wave) its quantisation is one too (half a step in a level). The gain
/// multiplies every run's FRF, displacement and force alike.
pub const COMMAND_GAIN: &str = "command_gain";

/// The name of the servo-valve's F_max = A P_s (N), the last parameter
/// when the flow-pressure law is fitted (theta holds ln(1 / F_max)). The
/// chamber's flow is r sqrt(1 - sign(r) f / F_max); on a sweep each bin
/// sees it as its describing function N at the force amplitude |S| X
/// there (`model::flow`), a factor on the valve's flow inside the loop:
/// A becomes A N in D and in the numerator. The rig is then the zero-load
/// one.
pub const FLOW_LAW: &str = "max_force_n";

/// How to fit.
#[derive(Debug, Clone, Copy)]
pub struct JointOptions {
    pub structure: Structure,
    pub intersample: Intersample,
    pub sample_rate_hz: f64,
    /// The P gain a1b0 is stated at.
    pub p_ref: f64,
    pub max_iterations: u64,
    /// Where the mode starts (Hz) and its damping.
    pub valve_start: (f64, f64),
    /// Where the piston's mass starts (kg).
    pub piston_start_kg: f64,
    /// Where the delay starts (s), and its upper bound (s); it is at least 0.
    pub delay_start_s: f64,
    pub max_delay_s: f64,
    /// Where the force FRFs' delay starts (s), when there is one; its bound
    /// is the delay's.
    pub force_delay_start_s: f64,
    /// Whether the piston's Coulomb seal friction is fitted (on the runs
    /// with amplitudes), as the last parameter [`FRICTION`], and where it
    /// starts (N).
    pub friction: bool,
    pub friction_start_n: f64,
    /// The friction's zero-crossing width v0 (m/s) when stated: its
    /// describing function is then F tanh(v / v0)'s
    /// ([`model::coulomb_load_per_newton`]).
    pub friction_smoothing_m_per_s: Option<f64>,
    /// Whether the seals' viscous damping is fitted with the friction.
    pub seal_damping: bool,
    /// Whether the logged command's gain ([`COMMAND_GAIN`]) is fitted,
    /// and where it starts.
    pub command_gain: bool,
    pub command_gain_start: f64,
    /// Whether the servo-valve's flow-pressure law ([`FLOW_LAW`]) is
    /// fitted (on the runs with amplitudes), and the F_max (N) it starts at.
    pub flow_law: bool,
    pub max_force_start_n: f64,
    /// Whether the law is tried at all: only where the data show its
    /// signature (the loaded runs' slow gain changing with the load, or
    /// harmonics in the loaded runs alone, which `analysis` reads) or the
    /// seals' friction is fitted, since any misfit of another cause (an FRF
    /// setting, a reading's nonlinearity) would otherwise buy its F_max.
    pub try_flow_law: bool,
    /// The rig's nameplate F_max = A P_s (N), when the manifest gives it:
    /// the law is then tried whatever the slow gain shows, freed from the
    /// nameplate, and held at it where the runs do not determine F_max.
    pub max_force_nameplate_n: Option<f64>,
    /// Whether the law is held at the nameplate's F_max (not fitted).
    pub flow_law_held: bool,
}

/// The joint estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct JointFit {
    pub structure: Structure,
    /// The rig, a1b0 at `p_ref`.
    pub rig: RigParams,
    pub delay_s: f64,
    /// Frequency (Hz) and damping ratio of the second-order mode, at the
    /// structure's place.
    pub mode: Option<(f64, f64)>,
    /// The piston's mass (kg), when the structure fits it.
    pub piston_mass_kg: Option<f64>,
    /// The force FRFs' own delay (s), when force FRFs were fitted with a
    /// structure that has a delay.
    pub force_delay_s: Option<f64>,
    /// The piston's Coulomb seal friction (N), when fitted.
    pub friction_n: Option<f64>,
    /// The seals' viscous damping (N s/m), when fitted.
    pub seal_damping_ns_per_m: Option<f64>,
    /// The logged command's gain ([`COMMAND_GAIN`]), when fitted.
    pub command_gain: Option<f64>,
    /// F_max = A P_s (N) of the flow-pressure law ([`FLOW_LAW`]), when
    /// fitted (among `names`) or held at the nameplate's (not among them).
    pub max_force_n: Option<f64>,
    /// beta1, a1b0, a2, a3, then delay (s), valve frequency (Hz) and
    /// damping as the structure has them, then the force FRFs' delay.
    pub params: Vec<f64>,
    /// Their names.
    pub names: Vec<&'static str>,
    /// Their covariance, scaled by the reduced chi-square as the per-run
    /// fit's is.
    pub covariance: DMatrix<f64>,
    pub std: Vec<f64>,
    /// The weighted cost (sum of squared weighted residuals) and its
    /// degrees of freedom, 2 bins - parameters.
    pub cost: f64,
    pub dof: usize,
    pub converged: bool,
    pub iterations: u64,
    /// The adequacy tests over every bin, and over each run's bins (in the
    /// order of the runs given, each with its share of the parameters).
    pub adequacy: Adequacy,
    pub per_run: Vec<Adequacy>,
}

impl JointFit {
    /// Why the optimum is not a physical rig, if it is not: a rig
    /// parameter not determined by the data (its std above its value, which
    /// is how a parameter running off towards 0 or infinity shows in a log
    /// parametrisation), a delay at its upper bound, or a mode with
    /// damping outside 0.05-5 or far above the band (20 times its top),
    /// where it is only a delay.
    /// The seals' viscous damping and its std where it is more than two
    /// stds below zero: a force that feeds the piston's motion.
    pub fn seal_damping_driving(&self) -> Option<(f64, f64)> {
        let c = self.seal_damping_ns_per_m?;
        let k = self.names.iter().position(|n| *n == SEAL_DAMPING)?;
        (c < -2.0 * self.std[k]).then_some((c, self.std[k]))
    }

    pub fn unphysical(&self, band_top_hz: f64, max_delay_s: f64) -> Option<String> {
        for (i, name) in self.structure.names().iter().enumerate().take(4) {
            let (v, sd) = (self.params[i], self.std[i]);
            if !(v.is_finite() && v > 0.0 && sd.is_finite() && sd < v) {
                return Some(format!(
                    "{name} = {v:.4e} with std {sd:.3e}: not determined by the data"
                ));
            }
        }
        let at_bound = |d: f64| d >= max_delay_s * (1.0 - 1e-9);
        if self.structure != Structure::Plain && at_bound(self.delay_s) {
            return Some(format!(
                "the delay sits at its bound identification.delay.max_s = {max_delay_s} s"
            ));
        }
        if self.force_delay_s.is_some_and(at_bound) {
            return Some(format!(
                "the force FRFs' delay sits at its bound identification.delay.max_s = {max_delay_s} s"
            ));
        }
        if let Some(mp) = self.piston_mass_kg {
            let sd = self.std[self.structure.piston_index()];
            if !(mp.is_finite() && mp > 0.0 && sd.is_finite() && sd < mp) {
                return Some(format!(
                    "piston_mass_kg = {mp:.4e} with std {sd:.3e}: not determined by the data"
                ));
            }
            // Far above the band a piston's mode is only a delay, unless
            // the seals rub: then the data resolve it from further up (a
            // 0.05 kg piston at 2 N came out 0.031 kg, its mode 29 times
            // the band's top, and the rig within 0.02 %, where the delay
            // alone is 0.14 % off: docs/accuracy.md).
            let hz = (self.rig.a2_n_per_m / mp).sqrt() / (2.0 * std::f64::consts::PI);
            if hz > 20.0 * band_top_hz && self.friction_n.is_none() {
                return Some(format!(
                    "the piston's mode at {hz:.0} Hz, over 20 times the band's top ({band_top_hz} Hz): only a delay there"
                ));
            }
        }
        if let (Some(f), Some(k)) = (
            self.friction_n,
            self.names.iter().position(|n| *n == FRICTION),
        ) && f < -2.0 * self.std[k]
        {
            return Some(format!(
                "{FRICTION} = {f:.3} N with std {:.3}: friction that drives the piston",
                self.std[k]
            ));
        }
        if let Some((c, sd)) = self.seal_damping_driving() {
            return Some(format!(
                "{SEAL_DAMPING} = {c:.3} N s/m with std {sd:.3}: damping that drives the piston"
            ));
        }
        if let Some((hz, zeta)) = self.mode {
            if !(0.05..=5.0).contains(&zeta) {
                return Some(format!("mode damping {zeta:.3} outside 0.05-5"));
            }
            if hz > 20.0 * band_top_hz {
                return Some(format!(
                    "mode at {hz:.0} Hz, over 20 times the band's top ({band_top_hz} Hz): only a delay there"
                ));
            }
        }
        None
    }
}

/// One bin of one run, as a pass reads it: made from the run's FRF where
/// it lies and the bin's known factor ([`JointProblem::bin`]).
#[derive(Debug, Clone, Copy)]
struct Bin {
    s: Complex<f64>,
    /// The run's specimen polynomial S(s) at `s`.
    sp: Complex<f64>,
    h: Complex<f64>,
    /// The hold's response (times S(s) for a force) times the aliases at
    /// the model they were evaluated for.
    known: Complex<f64>,
    /// Whether the bin is of a force FRF (its delay is the force's).
    force: bool,
    /// sqrt(2 / E|dH|^2): each of Re and Im then has unit variance.
    weight: f64,
    /// Index into `JointProblem::runs`.
    run: usize,
    /// Coulomb friction's describing function per newton at the bin's
    /// amplitude, j 4 / (pi X) (0 where none is fitted).
    coulomb: Complex<f64>,
    /// The displacement's amplitude X (m) at the bin, where the
    /// flow-pressure law is fitted (0: no load it could act on).
    amplitude_m: f64,
}

/// A run's specimen polynomial S(s) = m s^2 + c s + k, its P / P_ref and
/// whether its FRF is a force's.
#[derive(Debug, Clone, Copy)]
struct RunModel {
    mck: (f64, f64, f64),
    p_ratio: f64,
    force: bool,
}

/// A run's bins in a problem: its FRF where the run holds it, and which
/// of its bins the problem weighs.
#[derive(Debug, Clone)]
struct RunBins<'a> {
    frf: JointRun<'a>,
    /// The indices into the FRF of the bins weighed: those with a finite,
    /// positive variance (every stride-th of them in a coarse problem).
    at: Weighed,
    /// A coarse problem's own copy of a stored run's bins weighed, where
    /// the store could not keep it (else `frf` reads the store's copy; `at`
    /// indexes the copy either way): its passes would otherwise read every
    /// bin of the run to weigh one in `stride`.
    own: Option<FitData>,
}

/// The bins of a run a problem weighs, as indices into its FRF: a stride
/// where they are evenly spaced (every bin has a variance, nearly always:
/// a night's 2 M indices would be 8 MB), else listed.
#[derive(Debug, Clone)]
enum Weighed {
    /// `len` bins, every `step`-th from the first.
    Every {
        step: usize,
        len: usize,
    },
    Listed(Vec<u32>),
}

impl Weighed {
    /// The bins of `len` that `keep` keeps.
    fn of(len: usize, keep: impl Fn(usize) -> bool) -> Self {
        match (0..len).all(&keep) {
            true => Weighed::Every { step: 1, len },
            false => Weighed::Listed(
                (0..len)
                    .filter(|&i| keep(i))
                    .map(|i| u32::try_from(i).expect("an FRF of fewer than 2^32 bins"))
                    .collect(),
            ),
        }
    }

    fn len(&self) -> usize {
        match self {
            Weighed::Every { len, .. } => *len,
            Weighed::Listed(at) => at.len(),
        }
    }

    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The FRF's index of the `k`-th bin weighed.
    #[inline(always)]
    fn get(&self, k: usize) -> usize {
        match self {
            Weighed::Every { step, .. } => k * step,
            Weighed::Listed(at) => at[k] as usize,
        }
    }

    fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.len()).map(|k| self.get(k))
    }

    /// Every `stride`-th of these.
    fn every(&self, stride: usize) -> Self {
        match self {
            Weighed::Every { step, len } => Weighed::Every {
                step: step * stride,
                len: len.div_ceil(stride),
            },
            Weighed::Listed(at) => Weighed::Listed(at.iter().step_by(stride).copied().collect()),
        }
    }
}

/// The least-squares problem over every bin of every run. A bin is its
/// run's FRF read in place and its known factor, 16 bytes of its own
/// (with its index, 4; and its friction's load, 8, where one is fitted):
/// whole bins of 128 bytes would hold a night's 2 M in 0.27 GB a problem.
#[derive(Debug, Clone)]
struct JointProblem<'a> {
    frfs: Vec<RunBins<'a>>,
    /// Where each run's bins start in the problem's order, then their
    /// count: run by run, each run's bins together.
    starts: Vec<usize>,
    /// Each bin's known factor, in the problem's order.
    known: Vec<Complex<f64>>,
    /// Each bin's Coulomb describing function per newton over j
    /// ([`Bin::coulomb`]) where friction is fitted; else empty.
    coulomb: Vec<f64>,
    /// Whether bins carry their amplitude for the flow law.
    amplitudes: bool,
    /// The hold's sample rate (Hz), for the known factors.
    sample_rate_hz: f64,
    runs: Vec<RunModel>,
    /// Each run's FRF grid spacing (Hz).
    bin_hz: Vec<f64>,
    /// Each run's independent lag ([`JointRun::lag`]).
    lag: Vec<usize>,
    structure: Structure,
    /// Where the force FRFs' delay is in theta, when it is fitted.
    force_delay: Option<usize>,
    /// Where the friction is in theta, when it is fitted.
    friction: Option<usize>,
    /// Where the seals' viscous damping is in theta, when it is fitted.
    seal_damping: Option<usize>,
    /// Where the command's log gain is in theta, when it is fitted.
    command_gain: Option<usize>,
    /// Where ln(1 / F_max) is in theta, when the flow law is fitted.
    flow_law: Option<usize>,
    /// 1 / F_max (1/N) where the law is held at the nameplate's, else 0.
    kappa_held: f64,
    /// The sample period (s): the delay's unit in theta.
    period_s: f64,
    /// The command's intersample behaviour, for the aliases.
    intersample: Intersample,
}

/// Bins (their indices) and their known factors.
type KnownAt = Vec<(usize, Complex<f64>)>;

/// H and its derivatives with respect to theta at one bin.
struct BinEval {
    model: Complex<f64>,
    grad: [Complex<f64>; MAX_PARAMS],
}

/// Bins in a block of the Jacobian the covariance is factored from where
/// the normal equations are too ill-conditioned: 0.85 MB a block, where the
/// whole J of a night's 2 M bins is 0.24 GB.
const JACOBIAN_BLOCK: usize = 4096;

/// The most parameters a fit has: the valve-and-piston structure's eight,
/// the force FRFs' delay, the friction, the seals' damping, the command's
/// gain and the flow law's F_max.
const MAX_PARAMS: usize = 13;

/// The largest force amplitude over F_max the flow law's describing
/// function is taken at: at 1 the valve passes no flow against the load
/// for part of each cycle, where a fit's trial F_max may go.
const FLOW_RHO_MAX: f64 = 0.95;

/// The physical values at a point theta, computed once per pass over the
/// bins.
#[derive(Debug, Clone, Copy)]
struct Point {
    b1: f64,
    a1b0: f64,
    a2: f64,
    a3: f64,
    /// The delay (s), 0 for the plain structure.
    tau: f64,
    /// The force FRFs' delay (s).
    tau_force: f64,
    /// The mode's natural frequency (rad/s) and damping, if fitted.
    mode: Option<(f64, f64)>,
    /// The piston's mass (kg), 0 when not fitted.
    mp: f64,
    /// The Coulomb friction (N), 0 when not fitted.
    fc: f64,
    /// The seals' viscous damping (N s/m), 0 when not fitted.
    cv: f64,
    /// The logged command's gain, 1 when not fitted.
    g: f64,
    /// 1 / F_max (1/N) of the flow law, 0 when not fitted.
    kappa: f64,
}

impl Point {
    /// The rig (a1b0 referred to `p_ref`) with delays and no mode, piston,
    /// friction or seal damping.
    fn of_rig(rig: &RigParams, p_ref: f64, delay_s: f64, force_delay_s: f64) -> Point {
        Point {
            b1: rig.beta1_per_s,
            a1b0: rig.a1b0_n_per_m_s2 * p_ref / rig.p_gain,
            a2: rig.a2_n_per_m,
            a3: rig.a3_per_s,
            tau: delay_s,
            tau_force: force_delay_s,
            mode: None,
            mp: 0.0,
            fc: 0.0,
            cv: 0.0,
            g: 1.0,
            kappa: 0.0,
        }
    }
}

/// The flow law's loaded gain and rho at `bin` for the point `x`, the
/// piston's load `sp` and Q = `q` there: its describing function at the
/// bin's force amplitude |S| X (`model::flow`); past F_max (which the fit
/// may try) it is held at the edge of the law. None without the law, an
/// amplitude or a load.
#[inline(always)]
fn flow_at(
    bin: &Bin,
    x: &Point,
    sp: Complex<f64>,
    q: Complex<f64>,
) -> Option<(model::flow::FlowGain, f64)> {
    if !(x.kappa != 0.0 && bin.amplitude_m > 0.0 && sp.norm() > 0.0) {
        return None;
    }
    let rho = (x.kappa * sp.norm() * bin.amplitude_m).min(FLOW_RHO_MAX);
    model::flow::loaded_gain(q / sp, rho).map(|g| (g, rho))
}

/// Bins per chunk of a parallel pass: each chunk's sums are formed on one
/// thread and the chunks' added in their order, so the bits do not depend
/// on the thread count.
const CHUNK: usize = 2048;

impl<'a> JointProblem<'a> {
    fn n_params(&self) -> usize {
        self.structure.n_params()
            + usize::from(self.force_delay.is_some())
            + usize::from(self.friction.is_some())
            + usize::from(self.seal_damping.is_some())
            + usize::from(self.command_gain.is_some())
            + usize::from(self.flow_law.is_some())
    }

    fn names(&self) -> Vec<&'static str> {
        let mut names = self.structure.names().to_vec();
        if self.force_delay.is_some() {
            names.push(FORCE_DELAY);
        }
        if self.friction.is_some() {
            names.push(FRICTION);
        }
        if self.seal_damping.is_some() {
            names.push(SEAL_DAMPING);
        }
        if self.command_gain.is_some() {
            names.push(COMMAND_GAIN);
        }
        if self.flow_law.is_some() {
            names.push(FLOW_LAW);
        }
        names
    }

    /// The number of bins.
    fn len(&self) -> usize {
        self.known.len()
    }

    /// Run `r`'s FRF where its problem bins `ks` (its `k`-th to its
    /// last) lie: read once for them, from wherever the run keeps its bins.
    fn span(&self, r: usize, ks: std::ops::Range<usize>) -> Span<'_> {
        let run = &self.frfs[r];
        let range = match ks.is_empty() {
            true => 0..0,
            false => run.at.get(ks.start)..run.at.get(ks.end - 1) + 1,
        };
        match &run.own {
            Some(own) => own.bins().span(range),
            None => run.frf.bins.span(range),
        }
    }

    /// [`Self::span`] over all of run `r`'s problem bins.
    fn run_span(&self, r: usize) -> Span<'_> {
        self.span(r, 0..self.starts[r + 1] - self.starts[r])
    }

    /// Run `r`'s bin `k` (its `k`-th in the problem), `view` holding it: its
    /// s and its load S(s), with a spring's stiffening at the bin's
    /// amplitude.
    #[inline(always)]
    fn load(&self, view: &Span, r: usize, k: usize) -> (usize, Complex<f64>, Complex<f64>) {
        let frf = &self.frfs[r].frf;
        let i = self.frfs[r].at.get(k);
        let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * view.freq(i));
        let (m, c, stiffness) = self.runs[r].mck;
        let stiffening = match (frf.spring_cubic_n_per_m3, view.amplitude(i)) {
            (Some(k3), Some(a)) => 0.75 * k3 * a * a,
            _ => 0.0,
        };
        (i, s, s * s * m + s * c + (stiffness + stiffening))
    }

    /// Run `r`'s bin `k`: the hold's response at its frequency, times S(s)
    /// for a force.
    fn held(&self, view: &Span, r: usize, k: usize) -> Complex<f64> {
        let (i, _, sp) = self.load(view, r, k);
        self.held_at(view, r, i, sp)
    }

    /// [`Self::held`] at run `r`'s FRF bin `i`, its load `sp` there.
    fn held_at(&self, view: &Span, r: usize, i: usize, sp: Complex<f64>) -> Complex<f64> {
        let hold = hold_response(self.intersample, self.sample_rate_hz, view.freq(i));
        if self.runs[r].force { hold * sp } else { hold }
    }

    /// Run `r`'s bin `k` as the passes read it, `view` holding it.
    #[inline(always)]
    fn bin(&self, view: &Span, r: usize, k: usize) -> Bin {
        let (i, s, sp) = self.load(view, r, k);
        let flat = self.starts[r] + k;
        Bin {
            s,
            sp,
            h: view.h(i),
            known: self.known[flat],
            force: self.runs[r].force,
            weight: (2.0 / view.variance(i)).sqrt(),
            run: r,
            coulomb: Complex::new(0.0, self.coulomb.get(flat).copied().unwrap_or(0.0)),
            amplitude_m: match view.amplitude(i) {
                Some(a) if self.amplitudes => a,
                _ => 0.0,
            },
        }
    }

    /// The bins in `range` of the problem's order, run by run, each run's
    /// read once for them.
    fn bins_in(&self, range: std::ops::Range<usize>) -> impl Iterator<Item = Bin> + '_ {
        let (lo, hi) = (range.start, range.end);
        let first = self.starts.partition_point(|&s| s <= lo).saturating_sub(1);
        (first..self.frfs.len())
            .take_while(move |&r| self.starts[r] < hi)
            .flat_map(move |r| {
                let start = self.starts[r];
                let span = lo.max(start) - start..hi.min(self.starts[r + 1]) - start;
                let view = self.span(r, span.clone());
                span.map(move |k| self.bin(&view, r, k))
            })
    }

    /// The runs that have bins.
    fn runs_with_bins(&self) -> Vec<usize> {
        (0..self.frfs.len())
            .filter(|&r| self.starts[r + 1] > self.starts[r])
            .collect()
    }

    /// The problem over every `stride`-th bin of each run, run by run.
    fn every(&self, stride: usize) -> JointProblem<'a> {
        let stride = stride.max(1);
        let mut known = Vec::with_capacity(self.len() / stride + self.runs.len());
        let mut coulomb = Vec::new();
        let mut starts = Vec::with_capacity(self.starts.len());
        let mut frfs = Vec::with_capacity(self.frfs.len());
        for r in 0..self.frfs.len() {
            starts.push(known.len());
            let span = self.starts[r]..self.starts[r + 1];
            known.extend(span.clone().step_by(stride).map(|i| self.known[i]));
            if !self.coulomb.is_empty() {
                coulomb.extend(span.step_by(stride).map(|i| self.coulomb[i]));
            }
            frfs.push(self.coarse_bins(r, stride));
        }
        starts.push(known.len());
        JointProblem {
            frfs,
            starts,
            known,
            coulomb,
            amplitudes: self.amplitudes,
            sample_rate_hz: self.sample_rate_hz,
            runs: self.runs.clone(),
            bin_hz: self.bin_hz.iter().map(|h| h * stride as f64).collect(),
            lag: self.lag.clone(),
            structure: self.structure,
            force_delay: self.force_delay,
            friction: self.friction,
            seal_damping: self.seal_damping,
            command_gain: self.command_gain,
            flow_law: self.flow_law,
            kappa_held: self.kappa_held,
            period_s: self.period_s,
            intersample: self.intersample,
        }
    }

    /// Run `r`'s every `stride`-th bin weighed, a stored run's copied
    /// (into its store where it takes them).
    fn coarse_bins(&self, r: usize, stride: usize) -> RunBins<'a> {
        let run = &self.frfs[r];
        let at = run.at.every(stride);
        let store = match run.frf.bins {
            Bins::Stored { store, .. } if run.own.is_none() && !at.is_empty() => store,
            _ => {
                return RunBins {
                    frf: run.frf,
                    at,
                    own: run.own.clone(),
                };
            }
        };
        let view = self.run_span(r);
        let picked = |v: &dyn Fn(usize) -> f64| at.iter().map(v).collect();
        let own = FitData {
            freq_hz: picked(&|i| view.freq(i)),
            h: at.iter().map(|i| view.h(i)).collect(),
            variance: picked(&|i| view.variance(i)),
            suu: Vec::new(),
            bin_hz: run.frf.bin_hz,
            lag: run.frf.lag,
            amplitude_m: view
                .amplitude_m
                .is_some()
                .then(|| picked(&|i| view.amplitude(i).unwrap_or(0.0))),
        };
        let every = Weighed::Every {
            step: 1,
            len: at.len(),
        };
        match store.keep(&own) {
            Some(key) => RunBins {
                frf: JointRun {
                    bins: Bins::Stored {
                        store,
                        key,
                        len: own.h.len(),
                        amplitudes: own.amplitude_m.is_some(),
                    },
                    ..run.frf
                },
                at: every,
                own: None,
            },
            None => RunBins {
                frf: run.frf,
                at: every,
                own: Some(own),
            },
        }
    }

    fn point(&self, theta: &[f64]) -> Point {
        let tau = match self.structure {
            Structure::Plain => 0.0,
            _ => theta[4] * self.period_s,
        };
        Point {
            b1: theta[0].exp(),
            a1b0: theta[1].exp(),
            a2: theta[2].exp(),
            a3: theta[3].exp(),
            tau,
            tau_force: self.force_delay.map_or(tau, |k| theta[k] * self.period_s),
            mode: self
                .structure
                .place()
                .map(|_| (theta[5].exp(), theta[6].exp())),
            mp: if self.structure.piston() {
                theta[self.structure.piston_index()].exp()
            } else {
                0.0
            },
            fc: self.friction.map_or(0.0, |k| theta[k]),
            cv: self.seal_damping.map_or(0.0, |k| theta[k]),
            g: self.command_gain.map_or(1.0, |k| theta[k].exp()),
            kappa: self.flow_law.map_or(self.kappa_held, |k| theta[k].exp()),
        }
    }

    /// Run `r`'s linear model at `x` as a transfer function, for its
    /// aliases (module docs): x1/u = A V / D with the rig, mode, piston and
    /// seal damping at `x` and the specimen as stated, times S(s) for a
    /// force, with the run's delay.
    fn run_tf(&self, r: usize, x: &Point) -> Result<TransferFunction, crate::lti::LtiError> {
        let run = self.runs[r];
        let (m, c, k) = run.mck;
        let load = poly::trim_leading_zeros(&[m + x.mp, c + x.cv, k]);
        let q = poly::add(&poly::mul(&[1.0, x.a3], &load), &[x.a2, 0.0]);
        let sbq = poly::mul(&[1.0, x.b1], &q);
        let a = x.a1b0 * run.p_ratio;
        let place = match (self.structure.place(), run.force) {
            (Some(Place::Measurement), true) => None,
            (place, _) => place,
        };
        let (num, den) = match (x.mode, place) {
            (Some((wv, zeta)), Some(place)) => {
                let vden = [1.0, 2.0 * zeta * wv, wv * wv];
                let den = if place == Place::Loop {
                    poly::add(&poly::mul(&sbq, &vden), &[a * wv * wv])
                } else {
                    poly::mul(&poly::add(&sbq, &[a]), &vden)
                };
                (vec![x.g * a * wv * wv], den)
            }
            _ => (vec![x.g * a], poly::add(&sbq, &[a])),
        };
        let (num, tau) = if run.force {
            (poly::mul(&num, &[m, c, k]), x.tau_force)
        } else {
            (num, x.tau)
        };
        TransferFunction::with_delay(&num, &poly::trim_leading_zeros(&den), tau)
    }

    /// The known factor at every `stride`-th bin of each run for the model
    /// at `x`, with the bin's index: the hold (times S(s) for a force)
    /// times the aliases of its run's linear model ([`alias_factor`]), run
    /// by run side by side. None without a hold or for a point that gives
    /// no model.
    fn exact_known(&self, x: &Point, stride: usize) -> Option<KnownAt> {
        if self.intersample == Intersample::None {
            return None;
        }
        let per_run: Option<Vec<KnownAt>> = self
            .runs_with_bins()
            .into_par_iter()
            .with_max_len(1)
            .map(|r| {
                let tf = self.run_tf(r, x).ok()?;
                let at: Vec<usize> = (0..self.starts[r + 1] - self.starts[r])
                    .step_by(stride)
                    .collect();
                let known = self.run_known(r, &tf, &at);
                Some(
                    at.into_iter()
                        .map(|k| self.starts[r] + k)
                        .zip(known)
                        .collect(),
                )
            })
            .collect();
        Some(per_run?.concat())
    }

    /// Run `r`'s known factors at its bins `at` for its model `tf`: the
    /// hold (times S(s) for a force) times the aliases ([`alias_factor`]).
    fn run_known(&self, r: usize, tf: &TransferFunction, at: &[usize]) -> Vec<Complex<f64>> {
        let view = self.run_span(r);
        let loads: Vec<_> = at.iter().map(|&k| self.load(&view, r, k)).collect();
        let f: Vec<f64> = loads
            .iter()
            .map(|(_, s, _)| s.im / (2.0 * std::f64::consts::PI))
            .collect();
        let alias = alias_factor(self.intersample, 1.0 / self.period_s, tf, &f);
        loads
            .into_iter()
            .zip(alias)
            .map(|((i, _, sp), a)| self.held_at(&view, r, i, sp) * a)
            .collect()
    }

    /// Sets every bin's known factor to [`Self::exact_known`]'s at `x`, in
    /// place, run by run side by side. Whether it set them (not without a
    /// hold, or for a point that gives some run no model).
    fn set_exact_known(&mut self, x: &Point) -> bool {
        if self.intersample == Intersample::None {
            return false;
        }
        let runs = self.runs_with_bins();
        let tfs: Option<Vec<TransferFunction>> =
            runs.iter().map(|&r| self.run_tf(r, x).ok()).collect();
        let Some(tfs) = tfs else {
            return false;
        };
        let mut known = std::mem::take(&mut self.known);
        let this = &*self;
        // Each run's known factors, split off in order (a run without bins
        // has an empty span, and no model to evaluate).
        let mut slices = Vec::with_capacity(runs.len());
        let mut rest = known.as_mut_slice();
        for r in 0..this.frfs.len() {
            let (mine, tail) = rest.split_at_mut(this.starts[r + 1] - this.starts[r]);
            if !mine.is_empty() {
                slices.push((r, mine));
            }
            rest = tail;
        }
        slices
            .into_par_iter()
            .zip(tfs)
            .with_max_len(1)
            .for_each(|((r, out), tf)| {
                let at: Vec<usize> = (0..out.len()).collect();
                out.copy_from_slice(&this.run_known(r, &tf, &at));
            });
        self.known = known;
        true
    }

    /// Sets the known factors to the aliases at `x` where they would
    /// move some parameter by [`crate::fit::ALIAS_SETTLED`] of its std or more,
    /// as the per-run fit judges it ([`crate::fit::shift_in_stds`] on every
    /// [`crate::fit::ALIAS_PROBE_STRIDE`]-th bin of each run, `scale` the root
    /// of the reduced chi-square; 1 before a fit). Whether it set them.
    fn follow_aliases(&mut self, x: &Point, scale: f64) -> bool {
        let Some(probe) = self.exact_known(x, crate::fit::ALIAS_PROBE_STRIDE) else {
            return false;
        };
        let p = self.n_params();
        let mut a = DMatrix::zeros(p, p);
        let mut b = DVector::zeros(p);
        // The probe goes run by run: each run's FRF is read once for it.
        let mut view: Option<(usize, Span)> = None;
        for &(i, new) in &probe {
            let r = self.starts.partition_point(|&s| s <= i) - 1;
            if view.as_ref().is_none_or(|(at, _)| *at != r) {
                view = Some((r, self.run_span(r)));
            }
            let (_, v) = view.as_ref().expect("just read");
            let bin = &self.bin(v, r, i - self.starts[r]);
            let e = self.eval_at::<true>(bin, x);
            let d = e.model * (new / bin.known - 1.0) * bin.weight;
            for j in 0..p {
                let gj = e.grad[j] * bin.weight;
                b[j] += gj.re * d.re + gj.im * d.im;
                for k in 0..p {
                    let gk = e.grad[k] * bin.weight;
                    a[(j, k)] += gj.re * gk.re + gj.im * gk.im;
                }
            }
        }
        let share = probe.len() as f64 / self.len() as f64;
        let shift = crate::fit::shift_in_stds(&a, &b, share, scale);
        if !shift.is_some_and(|z| z.iter().any(|&z| z >= crate::fit::ALIAS_SETTLED)) {
            return false;
        }
        self.set_exact_known(x)
    }

    /// The flow law's share of the log-derivatives at one bin (`sp` and `q`
    /// the piston's load and Q there, `by_a` A's log-derivative of H times
    /// H, `flow` the loaded gain and rho): N moves with ln(1 / F_max)
    /// through rho, and with a2, a3 (and the piston's load) through the
    /// flow's lead over the force, arg(Q / S); its log-derivative of H is
    /// A's.
    #[inline(always)]
    fn add_flow_gradient(
        &self,
        grad: &mut [Complex<f64>; MAX_PARAMS],
        bin: &Bin,
        x: &Point,
        (sp, q): (Complex<f64>, Complex<f64>),
        by_a: Complex<f64>,
        (gain, rho): (model::flow::FlowGain, f64),
    ) {
        let s = bin.s;
        let by_n = by_a / gain.n;
        let change = |d_rho: f64, dq: Complex<f64>, dsp: Complex<f64>| {
            let d_phi0 = (dq / q - dsp / sp).im;
            let d_rho = d_rho + rho * (dsp / sp).re;
            by_n * model::flow::loaded_change(&gain, d_rho, d_phi0)
        };
        let zero = Complex::default();
        grad[2] += change(0.0, s * x.a2, zero);
        grad[3] += change(0.0, sp * x.a3, zero);
        if let Some(k) = self.flow_law {
            grad[k] = change(rho, zero, zero);
        }
        if self.structure.piston() {
            let dsp = s * s * x.mp;
            grad[self.structure.piston_index()] += change(0.0, (s + x.a3) * dsp, dsp);
        }
        if let Some(k) = self.friction {
            grad[k] += change(0.0, (s + x.a3) * bin.coulomb, bin.coulomb);
        }
        if let Some(k) = self.seal_damping {
            grad[k] += change(0.0, (s + x.a3) * s, s);
        }
    }

    /// The model at one bin, and with `GRAD` its log-derivatives (inlined
    /// into the passes over the bins, where it is nearly all the work).
    #[inline(always)]
    fn eval_at<const GRAD: bool>(&self, bin: &Bin, x: &Point) -> BinEval {
        let s = bin.s;
        let run = self.runs[bin.run];
        // The piston's load: the specimen's S(s), plus m_p s^2 for the
        // moving mass and the seals' friction as its describing function.
        let mut sp = bin.sp;
        if x.mp != 0.0 {
            sp += s * s * x.mp;
        }
        if x.fc != 0.0 {
            sp += bin.coulomb * x.fc;
        }
        if x.cv != 0.0 {
            sp += s * x.cv;
        }
        let q = (s + x.a3) * sp + s * x.a2;
        let one = Complex::new(1.0, 0.0);
        // The flow law's describing function scales the valve's gain A.
        let flow = flow_at(bin, x, sp, q);
        let a = flow.map_or(one, |(g, _)| g.n) * (x.a1b0 * run.p_ratio);
        let sb = s + x.b1;
        let sbq = sb * q;
        // Where the bin has the mode: every bin but a force's under a
        // measurement-path mode. In the loop V multiplies the valve's gain
        // (D = (s + beta1) Q + A V, numerator A V); outside it the output
        // (D = (s + beta1) Q + A, numerator A V). Each branch is the same
        // for every bin of a pass, so it costs no prediction misses.
        let place = match (self.structure.place(), bin.force) {
            (Some(Place::Measurement), true) => None,
            (place, _) => place,
        };
        let (d, num, inv_vden) = match (x.mode, place) {
            (Some((wv, zeta)), Some(place)) => {
                let inv = one / (s * s + s * (2.0 * zeta * wv) + wv * wv);
                let av = inv * (a * wv * wv);
                if place == Place::Loop {
                    (sbq + av, av, inv)
                } else {
                    (sbq + a, av, inv)
                }
            }
            _ => (sbq + a, a, one),
        };
        // exp(-s tau) on the imaginary axis: a rotation by -w tau.
        let tau = if bin.force { x.tau_force } else { x.tau };
        let known = if tau == 0.0 {
            bin.known * x.g
        } else {
            let (sin, cos) = (-s.im * tau).sin_cos();
            bin.known * Complex::new(x.g * cos, x.g * sin)
        };
        let inv_d = one / d;
        let h = num * inv_d * known;
        let mut grad = [Complex::default(); MAX_PARAMS];
        if GRAD {
            // x dH/dx for each log parameter (derived in the module docs'
            // notation): A enters as A V_loop, whose log-derivative of H is
            // (s + beta1) Q / D; V_out is a plain factor (log-derivative 1).
            let h_d = h * inv_d;
            let av = h_d * sbq;
            grad[0] = -h_d * q * x.b1;
            grad[1] = av;
            grad[2] = -h_d * sb * s * x.a2;
            grad[3] = -h_d * sb * sp * x.a3;
            if let Some(flow) = flow {
                self.add_flow_gradient(&mut grad, bin, x, (sp, q), av, flow);
            }
            if self.structure != Structure::Plain {
                let k = match (bin.force, self.force_delay) {
                    (true, Some(k)) => k,
                    _ => 4,
                };
                grad[k] = -s * self.period_s * h;
            }
            if self.structure.piston() {
                grad[self.structure.piston_index()] = -h_d * sb * (s + x.a3) * s * s * x.mp;
            }
            if let Some(k) = self.friction {
                grad[k] = -h_d * sb * (s + x.a3) * bin.coulomb;
            }
            if let Some(k) = self.seal_damping {
                grad[k] = -h_d * sb * (s + x.a3) * s;
            }
            if let Some(k) = self.command_gain {
                grad[k] = h;
            }
            if let (Some((wv, zeta)), Some(place)) = (x.mode, place) {
                // wv dV/dwv / V and zeta dV/dzeta / V, times the
                // log-derivative of H with respect to V.
                let by_v = if place == Place::Loop { av } else { h };
                grad[5] = by_v * s * (s + zeta * wv) * 2.0 * inv_vden;
                grad[6] = -by_v * s * (2.0 * zeta * wv) * inv_vden;
            }
        }
        BinEval { model: h, grad }
    }

    /// The weighted residuals stacked as [Re; Im], which the Jacobian's test
    /// differentiates (the solver uses [`Self::cost`]).
    #[cfg(test)]
    fn residuals(&self, theta: &[f64]) -> DVector<f64> {
        let x = self.point(theta);
        let n = self.len();
        let mut r = DVector::zeros(2 * n);
        for (i, b) in self.bins_in(0..n).enumerate() {
            let e = (b.h - self.eval_at::<false>(&b, &x).model) * b.weight;
            r[i] = e.re;
            r[n + i] = e.im;
        }
        r
    }

    /// J at theta, the weighted residuals' derivatives, in row blocks of
    /// [`JACOBIAN_BLOCK`] bins (each block its bins' real rows, then their
    /// imaginary ones), for [`crate::fit::covariance_streamed`].
    fn jacobian_blocks(&self, theta: &[f64], emit: &mut dyn FnMut(DMatrix<f64>)) {
        let x = self.point(theta);
        let p = self.n_params();
        let n = self.len();
        for start in (0..n).step_by(JACOBIAN_BLOCK) {
            let block = start..(start + JACOBIAN_BLOCK).min(n);
            let m = block.len();
            let mut jac = DMatrix::zeros(2 * m, p);
            for (i, b) in self.bins_in(block).enumerate() {
                let g = self.eval_at::<true>(&b, &x).grad;
                for j in 0..p {
                    jac[(i, j)] = -g[j].re * b.weight;
                    jac[(m + i, j)] = -g[j].im * b.weight;
                }
            }
            emit(jac);
        }
    }

    #[cfg(test)]
    fn jacobian_matrix(&self, theta: &[f64]) -> DMatrix<f64> {
        let x = self.point(theta);
        let n = self.len();
        let p = self.n_params();
        let mut jac = DMatrix::zeros(2 * n, p);
        for (i, b) in self.bins_in(0..n).enumerate() {
            let g = self.eval_at::<true>(&b, &x).grad;
            for j in 0..p {
                jac[(i, j)] = -g[j].re * b.weight;
                jac[(n + i, j)] = -g[j].im * b.weight;
            }
        }
        jac
    }

    /// The problem's bins in chunks of [`CHUNK`], side by side.
    fn chunks(&self) -> impl IndexedParallelIterator<Item = std::ops::Range<usize>> + '_ {
        let n = self.len();
        (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(move |c| c * CHUNK..((c + 1) * CHUNK).min(n))
    }

    /// The weighted cost r^T r, in one parallel pass (bin by bin and chunk
    /// by chunk in the order [`Self::normal`] adds it).
    fn cost(&self, theta: &[f64]) -> f64 {
        let x = self.point(theta);
        let partial: Vec<f64> = self
            .chunks()
            .map(|chunk| {
                let mut cost = 0.0;
                for b in self.bins_in(chunk) {
                    cost += ((b.h - self.eval_at::<false>(&b, &x).model) * b.weight).norm_sqr();
                }
                cost
            })
            .collect();
        let mut cost = 0.0;
        for c in &partial {
            cost += c;
        }
        cost
    }

    /// r^T r, J^T J and J^T r, in one parallel pass without forming J: per
    /// bin the residual's and the gradient's real and imaginary parts, each
    /// weighted, added into the cost and the p x p and p sums.
    fn normal(&self, theta: &[f64]) -> Normal {
        match self.n_params() {
            4 => self.normal_p::<4>(theta),
            5 => self.normal_p::<5>(theta),
            6 => self.normal_p::<6>(theta),
            7 => self.normal_p::<7>(theta),
            8 => self.normal_p::<8>(theta),
            9 => self.normal_p::<9>(theta),
            10 => self.normal_p::<10>(theta),
            11 => self.normal_p::<11>(theta),
            12 => self.normal_p::<12>(theta),
            p => unreachable!("{p} parameters"),
        }
    }

    /// [`Self::normal`] with the parameter count fixed at compile time, so
    /// the sums unroll and vectorise; only the upper triangle of J^T J is
    /// summed (each element the same products in the same order as the
    /// full square would add, so the bits are those of the full sum).
    fn normal_p<const P: usize>(&self, theta: &[f64]) -> Normal {
        debug_assert_eq!(P, self.n_params());
        let x = self.point(theta);
        let partial: Vec<(f64, [[f64; P]; P], [f64; P])> = self
            .chunks()
            .map(|chunk| {
                let mut cost = 0.0;
                let mut a = [[0.0; P]; P];
                let mut g = [0.0; P];
                for b in self.bins_in(chunk) {
                    let e = self.eval_at::<true>(&b, &x);
                    let r = (b.h - e.model) * b.weight;
                    // As [`Self::cost`] adds it, to the bit.
                    cost += r.norm_sqr();
                    // The bin's two rows of J (Re and Im) are -grad * weight.
                    let mut re = [0.0; P];
                    let mut im = [0.0; P];
                    for k in 0..P {
                        re[k] = e.grad[k].re * b.weight;
                        im[k] = e.grad[k].im * b.weight;
                    }
                    for i in 0..P {
                        g[i] -= re[i] * r.re + im[i] * r.im;
                        for j in i..P {
                            a[i][j] += re[i] * re[j] + im[i] * im[j];
                        }
                    }
                }
                (cost, a, g)
            })
            .collect();
        let mut cost = 0.0;
        let mut a = DMatrix::zeros(P, P);
        let mut g = DVector::zeros(P);
        for (pc, pa, pg) in &partial {
            cost += pc;
            for i in 0..P {
                g[i] += pg[i];
                for j in i..P {
                    a[(i, j)] += pa[i][j];
                }
            }
        }
        for i in 0..P {
            for j in 0..i {
                a[(i, j)] = a[(j, i)];
            }
        }
        Normal { cost, a, g }
    }
}

impl JointProblem<'_> {
    /// [`crate::fit::correlated_covariance`] at `theta`: each bin's score, and
    /// its place along its run's FRF in bins, paired up to its run's lag
    /// less one bins apart (the lag being the first at which bins are
    /// independent).
    fn correlated_covariance(
        &self,
        theta: &[f64],
        a_inv: &DMatrix<f64>,
        dof: usize,
    ) -> DMatrix<f64> {
        let x = self.point(theta);
        let p = self.n_params();
        let n = self.len();
        let mut scores = DMatrix::zeros(n, p);
        let mut position = Vec::with_capacity(n);
        for (i, b) in self.bins_in(0..n).enumerate() {
            let e = self.eval_at::<true>(&b, &x);
            let r = (b.h - e.model) * b.weight;
            for k in 0..p {
                scores[(i, k)] = (e.grad[k].re * r.re + e.grad[k].im * r.im) * b.weight;
            }
            let f = b.s.im / (2.0 * std::f64::consts::PI);
            position.push((b.run, f / self.bin_hz[b.run]));
        }
        let reach: Vec<f64> = self.lag.iter().map(|l| (l - 1) as f64).collect();
        crate::fit::correlated_covariance(&scores, &position, &reach, a_inv, 2 * n, dof)
    }

    /// Whether any run's bins share data with their neighbours.
    fn correlated(&self) -> bool {
        self.lag.iter().any(|&l| l > 1)
    }

    /// The adequacy tests at `theta`: over every bin, and per run with the
    /// run's share of the parameters.
    fn adequacy(&self, theta: &[f64]) -> (Adequacy, Vec<Adequacy>) {
        let x = self.point(theta);
        let p = self.n_params();
        let total = self.len().max(1);
        let mut pooled = Sums::default();
        let mut per_run = Vec::with_capacity(self.runs.len());
        for (r, &bin_hz) in self.bin_hz.iter().enumerate() {
            let lag = self.lag[r];
            let bins: Vec<Bin> = self.bins_in(self.starts[r]..self.starts[r + 1]).collect();
            let freq: Vec<f64> = bins
                .iter()
                .map(|b| b.s.im / (2.0 * std::f64::consts::PI))
                .collect();
            let h: Vec<Complex<f64>> = bins.iter().map(|b| b.h).collect();
            let model: Vec<Complex<f64>> = bins
                .iter()
                .map(|b| self.eval_at::<false>(b, &x).model)
                .collect();
            let variance: Vec<f64> = bins.iter().map(|b| 2.0 / (b.weight * b.weight)).collect();
            let mut sums = Sums::default();
            sums.add(
                &Residuals {
                    freq_hz: &freq,
                    h: &h,
                    model: &model,
                    variance: &variance,
                },
                bin_hz,
                lag,
            );
            let share = (p * bins.len()).div_ceil(total);
            per_run.push(sums.finish(share, lag));
            pooled += sums;
        }
        let widest = self.lag.iter().copied().max().unwrap_or(1);
        (pooled.finish(p, widest), per_run)
    }
}

fn problem<'a>(runs: &[JointRun<'a>], opts: &JointOptions) -> Result<JointProblem<'a>, FitError> {
    for run in runs {
        let (freq, h, variance) = run.bins.lengths();
        if freq != h || h != variance {
            return Err(FitError::LengthMismatch { freq, h, variance });
        }
    }
    let models = runs
        .iter()
        .map(|run| RunModel {
            mck: run.specimen.mck(),
            p_ratio: run.p_gain / opts.p_ref,
            force: run.output == Output::Force,
        })
        .collect();
    let bin_hz = runs.iter().map(|r| r.bin_hz).collect();
    let lag = runs.iter().map(|r| r.lag.max(1)).collect();
    let has_force = runs.iter().any(|r| r.output == Output::Force);
    let force_delay =
        (has_force && opts.structure != Structure::Plain).then(|| opts.structure.n_params());
    let friction = (opts.friction && runs.iter().any(|r| r.bins.has_amplitudes()))
        .then(|| opts.structure.n_params() + usize::from(force_delay.is_some()));
    let seal_damping = friction.filter(|_| opts.seal_damping).map(|k| k + 1);
    let command_gain = opts.command_gain.then(|| {
        opts.structure.n_params()
            + usize::from(force_delay.is_some())
            + usize::from(friction.is_some())
            + usize::from(seal_damping.is_some())
    });
    let flow_law = (opts.flow_law && runs.iter().any(|r| r.bins.has_amplitudes())).then(|| {
        opts.structure.n_params()
            + usize::from(force_delay.is_some())
            + usize::from(friction.is_some())
            + usize::from(seal_damping.is_some())
            + usize::from(command_gain.is_some())
    });
    let mut problem = JointProblem {
        frfs: Vec::with_capacity(runs.len()),
        starts: Vec::with_capacity(runs.len() + 1),
        // Sized once, for every bin (those without a variance are few):
        // grown by doubling it could take twice its size.
        known: Vec::with_capacity(runs.iter().map(|r| r.bins.len()).sum()),
        coulomb: Vec::new(),
        amplitudes: opts.flow_law || opts.flow_law_held,
        sample_rate_hz: opts.sample_rate_hz,
        runs: models,
        bin_hz,
        lag,
        structure: opts.structure,
        force_delay,
        friction,
        seal_damping,
        command_gain,
        flow_law,
        kappa_held: match opts.max_force_nameplate_n {
            Some(f) if opts.flow_law_held && !opts.flow_law => 1.0 / f,
            _ => 0.0,
        },
        period_s: 1.0 / opts.sample_rate_hz,
        intersample: opts.intersample,
    };
    for run in runs {
        problem.weigh(run, opts);
    }
    let n = problem.known.len();
    problem.starts.push(n);
    if !problem.coulomb.is_empty() {
        problem.coulomb.resize(n, 0.0);
    }
    Ok(problem)
}

impl<'a> JointProblem<'a> {
    /// `run`'s bins added, its FRF read once for them: those with a finite,
    /// positive variance, with their Coulomb describing function where
    /// friction is fitted and their known factors.
    fn weigh(&mut self, run: &JointRun<'a>, opts: &JointOptions) {
        let (r, n) = (self.frfs.len(), self.known.len());
        let all = run.bins.all();
        let at = Weighed::of(run.bins.len(), |i| {
            all.variance(i).is_finite() && all.variance(i) > 0.0
        });
        if let (true, Some(a)) = (opts.friction, &all.amplitude_m) {
            self.coulomb.resize(n, 0.0);
            self.coulomb.extend(at.iter().map(|i| {
                let (f, a) = (all.freq(i), a[i]);
                if a > 0.0 {
                    model::coulomb_load_per_newton(f, a, opts.friction_smoothing_m_per_s)
                } else {
                    0.0
                }
            }));
        }
        self.starts.push(n);
        self.frfs.push(RunBins {
            frf: *run,
            at,
            own: None,
        });
        for k in 0..self.frfs[r].at.len() {
            let known = self.held(&all, r, k);
            self.known.push(known);
        }
    }
}

/// Fit the rig jointly to `runs`, starting from `start` (the sequential
/// estimate, a1b0 at `opts.p_ref`), the delay from `opts.delay_start_s` and
/// the valve mode from `opts.valve_start`.
pub fn joint_fit(
    runs: &[JointRun<'_>],
    start: &RigParams,
    opts: &JointOptions,
) -> Result<JointFit, FitError> {
    let (problem, optimum) = fit_to_optimum(runs, start, opts)?;
    finish(&problem, optimum, opts)
}

/// The problem over `runs` and its optimum from `start` (as [`joint_fit`]
/// reaches it), its aliases those of the optimum's last leg.
fn fit_to_optimum<'a>(
    runs: &[JointRun<'a>],
    start: &RigParams,
    opts: &JointOptions,
) -> Result<(JointProblem<'a>, Optimum), FitError> {
    let mut problem = problem(runs, opts)?;
    let theta0 = start_theta(&problem, start, opts)?;
    let optimum = settle(&mut problem, opts, theta0)?;
    Ok((problem, optimum))
}

/// As [`joint_fit`], by way of the optimum on every `stride`-th bin: from
/// there the fit on every bin takes a few iterations where a start from the
/// sequential estimate takes a dozen, each a pass over all the bins. The
/// optimum is the same (the last leg runs to convergence on every bin); a
/// failure on the fewer bins falls back to the plain fit.
pub(super) fn joint_fit_staged(
    runs: &[JointRun<'_>],
    start: &RigParams,
    opts: &JointOptions,
    stride: usize,
) -> Result<JointFit, FitError> {
    let mut problem = problem(runs, opts)?;
    let mut coarse = problem.every(stride);
    let theta0 = start_theta(&coarse, start, opts)?;
    coarse.follow_aliases(&coarse.point(&theta0), 1.0);
    let near = match Leg::from(&coarse, start, opts, opts.max_iterations) {
        Ok(leg) => leg.optimum.theta,
        Err(_) => start_theta(&problem, start, opts)?,
    };
    let optimum = settle(&mut problem, opts, near)?;
    finish(&problem, optimum, opts)
}

/// The most re-evaluations of the aliases [`settle`] makes after its first
/// leg. One or two settle them where the images are small; a mode above
/// the Nyquist frequency folds into the band, its images move with it, and
/// each pass then takes a fixed share of the distance left (at 200 Hz with
/// a 110 Hz mode in the loop the delay is 2.5e-5 off after eight and
/// within 2e-6 after twelve). The loop stops as soon as the aliases would
/// move no parameter by [`crate::fit::ALIAS_SETTLED`] of its std, so a rig that
/// needs none pays for none.
const ALIAS_PASSES: usize = 12;

/// Levenberg-Marquardt on `problem` from `theta0` with the hold's aliases
/// those of the model it finds (docs/methods.md, "The joint fit"): evaluated at `theta0`, then
/// at each optimum, and fitted again from there while they would move it
/// by [`crate::fit::ALIAS_SETTLED`] of its stated std or more. The aliases the
/// problem is left with are those of the optimum's last leg.
fn settle(
    problem: &mut JointProblem,
    opts: &JointOptions,
    theta0: Vec<f64>,
) -> Result<Optimum, FitError> {
    problem.follow_aliases(&problem.point(&theta0), 1.0);
    let leg = |problem: &JointProblem, theta, before| {
        Leg::run(
            problem,
            solver(problem, opts)?,
            theta,
            None,
            opts.max_iterations,
            before,
        )
    };
    let mut optimum = leg(problem, theta0, 0)?.optimum;
    let dof = (2 * problem.len())
        .saturating_sub(problem.n_params())
        .max(1);
    for _ in 0..ALIAS_PASSES {
        let scale = (optimum.cost / dof as f64).sqrt();
        if !problem.follow_aliases(&problem.point(&optimum.theta), scale) {
            break;
        }
        optimum = leg(problem, optimum.theta, optimum.iterations)?.optimum;
    }
    Ok(optimum)
}

/// Where Levenberg-Marquardt stopped.
#[derive(Debug, Clone)]
struct Optimum {
    theta: Vec<f64>,
    cost: f64,
    converged: bool,
    iterations: u64,
    /// The cost and normal equations at `theta`, from the solver's last
    /// pass.
    normal: Normal,
}

/// The solver's view of a problem borrowed rather than copied (the valve
/// mode's two starts share one).
struct Borrowed<'a, 'b>(&'a JointProblem<'b>);

/// The solver sees the cost and the normal equations together
/// ([`Normal`]): the bins far outnumber the parameters.
impl Jacobian for Borrowed<'_, '_> {
    type Param = DVector<f64>;
    type Jacobian = Normal;

    fn jacobian(&self, param: &Self::Param) -> Result<Self::Jacobian, ArgminError> {
        Ok(self.0.normal(param.as_slice()))
    }
}

/// The parameters Levenberg-Marquardt starts from for `problem`: the rig
/// `start` (a1b0 referred to `opts.p_ref`) and the delays, mode, piston and
/// friction `opts` start at.
fn start_theta(
    problem: &JointProblem,
    start: &RigParams,
    opts: &JointOptions,
) -> Result<Vec<f64>, FitError> {
    let p = problem.n_params();
    let mut theta0 = rig_theta(start, opts.p_ref).to_vec();
    let fs = opts.sample_rate_hz;
    let delay = |d: f64| (d * fs).clamp(0.0, opts.max_delay_s * fs);
    if opts.structure != Structure::Plain {
        theta0.push(delay(opts.delay_start_s));
    }
    if opts.structure.place().is_some() {
        theta0.push((2.0 * std::f64::consts::PI * opts.valve_start.0).ln());
        theta0.push(opts.valve_start.1.ln());
    }
    if opts.structure.piston() {
        theta0.push(opts.piston_start_kg.ln());
    }
    if problem.force_delay.is_some() {
        theta0.push(delay(opts.force_delay_start_s));
    }
    if problem.friction.is_some() {
        theta0.push(opts.friction_start_n);
    }
    if problem.seal_damping.is_some() {
        theta0.push(0.0);
    }
    if problem.command_gain.is_some() {
        theta0.push(opts.command_gain_start.ln());
    }
    if problem.flow_law.is_some() {
        theta0.push(-opts.max_force_start_n.ln());
    }
    if !theta0.iter().all(|t| t.is_finite()) {
        return Err(FitError::NoSolution);
    }
    if 2 * problem.len() <= p {
        return Err(FitError::NoSolution);
    }
    Ok(theta0)
}

/// Levenberg-Marquardt run for a number of iterations: where it stopped,
/// and what it takes to go on from there as one longer run would.
struct Leg {
    optimum: Optimum,
    solver: LevenbergMarquardt,
}

impl Leg {
    /// At most `max_iterations` from the start `opts` and `start` give.
    fn from(
        problem: &JointProblem,
        start: &RigParams,
        opts: &JointOptions,
        max_iterations: u64,
    ) -> Result<Leg, FitError> {
        Self::run(
            problem,
            solver(problem, opts)?,
            start_theta(problem, start, opts)?,
            None,
            max_iterations,
            0,
        )
    }

    /// Up to `more` iterations further, unless it has converged.
    fn go_on(self, problem: &JointProblem, more: u64) -> Result<Leg, FitError> {
        if self.optimum.converged || more == 0 {
            return Ok(self);
        }
        let Leg { optimum, solver } = self;
        Self::run(
            problem,
            solver.resumed(),
            optimum.theta,
            Some(optimum.normal),
            more,
            optimum.iterations,
        )
    }

    fn run(
        problem: &JointProblem,
        solver: LevenbergMarquardt,
        theta0: Vec<f64>,
        normal: Option<Normal>,
        max_iterations: u64,
        iterations_before: u64,
    ) -> Result<Leg, FitError> {
        let mut result = Executor::new(Borrowed(problem), solver)
            .configure(|s| {
                let s = s.param(DVector::from_vec(theta0)).max_iters(max_iterations);
                match normal {
                    Some(n) => s.jacobian(n),
                    None => s,
                }
            })
            .run()?;
        let state = &mut result.state;
        let converged = state.get_termination_reason() == Some(&TerminationReason::SolverConverged);
        let iterations = iterations_before + state.get_iter();
        let theta = state.take_param().ok_or(FitError::NoSolution)?;
        let normal = state.take_jacobian().ok_or(FitError::NoSolution)?;
        Ok(Leg {
            optimum: Optimum {
                theta: theta.iter().copied().collect(),
                cost: normal.cost,
                converged,
                iterations,
                normal,
            },
            solver: result.solver,
        })
    }
}

/// The fit at an optimum: the covariance from the Jacobian there, the
/// parameters in physical units, and the adequacy tests.
fn finish(
    problem: &JointProblem,
    optimum: Optimum,
    opts: &JointOptions,
) -> Result<JointFit, FitError> {
    let Optimum {
        theta,
        cost,
        converged,
        iterations,
        normal,
    } = optimum;
    let p = problem.n_params();
    let names = problem.names();
    let dof = 2 * problem.len() - p;
    let scale = cost / dof as f64;
    let cov_theta = theta_covariance(problem, &theta, &normal, scale)?;
    // Bins that share data (a window's kernel, the LPM's transient) have
    // correlated errors: the sandwich over their range.
    let cov_theta = if problem.correlated() && scale > 0.0 {
        problem.correlated_covariance(&theta, &(&cov_theta / scale), dof)
    } else {
        cov_theta
    };
    let (params, factors) = physical(problem, &theta, opts);
    let covariance = DMatrix::from_fn(p, p, |i, j| cov_theta[(i, j)] * factors[i] * factors[j]);
    let std = (0..p).map(|i| covariance[(i, i)].sqrt()).collect();
    let (adequacy, per_run) = problem.adequacy(&theta);
    Ok(JointFit {
        structure: opts.structure,
        rig: RigParams {
            beta1_per_s: params[0],
            a1b0_n_per_m_s2: params[1],
            a2_n_per_m: params[2],
            a3_per_s: params[3],
            p_gain: opts.p_ref,
        },
        delay_s: if opts.structure == Structure::Plain {
            0.0
        } else {
            params[4]
        },
        mode: opts.structure.place().map(|_| (params[5], params[6])),
        piston_mass_kg: opts
            .structure
            .piston()
            .then(|| params[opts.structure.piston_index()]),
        force_delay_s: problem.force_delay.map(|k| params[k]),
        friction_n: problem.friction.map(|k| params[k]),
        seal_damping_ns_per_m: problem.seal_damping.map(|k| params[k]),
        command_gain: problem.command_gain.map(|k| params[k]),
        max_force_n: problem
            .flow_law
            .map(|k| params[k])
            .or((problem.kappa_held > 0.0).then(|| 1.0 / problem.kappa_held)),
        params,
        names,
        covariance,
        std,
        cost,
        dof,
        converged,
        iterations,
        adequacy,
        per_run,
    })
}

/// The covariance of theta at the optimum `theta` (`normal` the solver's
/// last normal equations there, `scale` the reduced chi-square): from the
/// normal equations when they are well conditioned enough, otherwise from
/// J itself, formed here. An error names the parameter the bins do not
/// determine.
fn theta_covariance(
    problem: &JointProblem,
    theta: &[f64],
    normal: &Normal,
    scale: f64,
) -> Result<DMatrix<f64>, FitError> {
    if let Some(cov) = covariance_from_normal(&normal.a, scale) {
        return Ok(cov);
    }
    covariance_streamed(
        problem.n_params(),
        |emit| problem.jacobian_blocks(theta, emit),
        scale,
    )
    .map_err(|e| FitError::NotIdentifiable {
        parameter: problem.names()[e.column].to_string(),
        bins: problem.len(),
        matrix: "joint fit's Jacobian at the optimum",
        ratio: e.ratio,
    })
}

/// [`joint_fit`]'s parameters (physical units) and whether it converged,
/// without the covariance's sandwich or the adequacy tests, which cost a
/// pass over the bins and a run's worth of arrays each: what a jackknife's
/// refit uses. It fails where [`joint_fit`] would.
pub(super) fn joint_fit_params(
    runs: &[JointRun<'_>],
    start: &RigParams,
    opts: &JointOptions,
) -> Result<(Vec<f64>, bool), FitError> {
    let (problem, optimum) = fit_to_optimum(runs, start, opts)?;
    let dof = 2 * problem.len() - problem.n_params();
    theta_covariance(
        &problem,
        &optimum.theta,
        &optimum.normal,
        optimum.cost / dof as f64,
    )?;
    Ok((
        physical(&problem, &optimum.theta, opts).0,
        optimum.converged,
    ))
}

/// The parameters at `theta` in physical units, and each one's derivative
/// with respect to its element of theta: x = exp(theta) for the log
/// parameters (dx = x dtheta), the delays in seconds, the mode's frequency
/// in Hz.
fn physical(problem: &JointProblem, theta: &[f64], opts: &JointOptions) -> (Vec<f64>, Vec<f64>) {
    let mut params: Vec<f64> = theta[..4].iter().map(|t| t.exp()).collect();
    let mut factors = params.clone();
    if opts.structure != Structure::Plain {
        params.push(theta[4] * problem.period_s);
        factors.push(problem.period_s);
    }
    if opts.structure.place().is_some() {
        let hz = theta[5].exp() / (2.0 * std::f64::consts::PI);
        params.push(hz);
        factors.push(hz);
        params.push(theta[6].exp());
        factors.push(theta[6].exp());
    }
    if opts.structure.piston() {
        let mp = theta[opts.structure.piston_index()].exp();
        params.push(mp);
        factors.push(mp);
    }
    if let Some(k) = problem.force_delay {
        params.push(theta[k] * problem.period_s);
        factors.push(problem.period_s);
    }
    if let Some(k) = problem.friction {
        params.push(theta[k]);
        factors.push(1.0);
    }
    if let Some(k) = problem.seal_damping {
        params.push(theta[k]);
        factors.push(1.0);
    }
    if let Some(k) = problem.command_gain {
        params.push(theta[k].exp());
        factors.push(theta[k].exp());
    }
    if let Some(k) = problem.flow_law {
        // F_max = exp(-theta): dF = -F dtheta.
        let fmax = (-theta[k]).exp();
        params.push(fmax);
        factors.push(-fmax);
    }
    (params, factors)
}

/// The rig's log parameters, a1b0 referred to `p_ref`.
fn rig_theta(rig: &RigParams, p_ref: f64) -> [f64; 4] {
    [
        rig.beta1_per_s.ln(),
        (rig.a1b0_n_per_m_s2 * p_ref / rig.p_gain).ln(),
        rig.a2_n_per_m.ln(),
        rig.a3_per_s.ln(),
    ]
}

/// Accepted steps of no gain in a row that stop a joint fit unconverged.
const STALL_STEPS: u32 = 3;

/// Levenberg-Marquardt with the delay (in samples) held within 0 and its
/// bound: a negative delay is acausal.
fn solver(problem: &JointProblem, opts: &JointOptions) -> Result<LevenbergMarquardt, FitError> {
    let p = problem.n_params();
    // Damping moved by 3 rather than 10: measured on the seven-run bench,
    // the structure selection takes about a fifth fewer passes over the bins.
    // A structure whose extra parameters the data do not fix (a mode or a
    // piston on a rig without one) stalls: three steps of no gain end it
    // where it took every allowed iteration over every bin, unconverged
    // either way.
    let solver = LevenbergMarquardt::new()
        .with_lambda(1e-3, 3.0)?
        .with_stall_limit(STALL_STEPS)
        .with_settled_cost(crate::fit::SETTLED_COST);
    if opts.structure == Structure::Plain {
        return Ok(solver);
    }
    let mut lower = DVector::from_element(p, f64::NEG_INFINITY);
    let mut upper = DVector::from_element(p, f64::INFINITY);
    for k in std::iter::once(4).chain(problem.force_delay) {
        lower[k] = 0.0;
        upper[k] = opts.max_delay_s * opts.sample_rate_hz;
    }
    if opts.structure == Structure::DelayValvePiston {
        // On a rig with the valve's mode alone the piston's mass runs
        // towards zero; a ten-thousandth of its start puts its mode
        // sqrt(a2 / m_p) a hundred times higher, where no data see it, and
        // the bound stops the fit there rather than after every iteration
        // it is allowed.
        lower[problem.structure.piston_index()] = (1e-4 * opts.piston_start_kg).ln();
    }
    Ok(solver.with_bounds(lower, upper)?)
}

mod select;
pub use select::{
    Candidate, Choice, FTest, HAUSMAN_Z, JointIdentification, P_SIGNIFICANT, RunSpread, Selection,
    StructureSpread, WEIGHT_FLOOR, identify, refit, run_spread, select,
};

#[cfg(test)]
mod tests;
