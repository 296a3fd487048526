//! The time-domain route for a rig with seal friction, which servoid does
//! not ship (docs/accuracy.md, "Seal friction: two routes"): the nonlinear
//! model's simulation under each run's logged command, fitted to the logged
//! displacements of all runs at once (simulation error, as MATLAB's
//! nlgreyest does), started from the frequency-domain joint fit. It is kept
//! here, beside the comparison in `joint.rs` that chose against it, so the
//! measurement can be rerun.
//!
//! The model is servoid's simulated plant (docs/model.md): the hydraulic
//! system of Eq. 10 with the piston's mass m_p and its Coulomb friction
//! F tanh(x2 / v0) in the force balance (m + m_p) x2' = f - g - F tanh(x2 / v0),
//! the joint fit's sensor delay held. Each run's LVDT offset and drift are
//! projected out of its residuals (a line in time per run).
//!
//! Levenberg-Marquardt (servoid's) over (beta1, a1b0, a2, a3, m_p, F, ln v0)
//! scaled by their starts, with forward-difference Jacobians (columns in
//! parallel); each simulation is Dormand-Prince at servoid's default
//! tolerances.

use argmin::core::{Error, Executor, Jacobian, Operator, State, TerminationReason};
use nalgebra::{DMatrix, DVector};

use servoid::fit::lm::LevenbergMarquardt;
use servoid::frf::{Detrend, detrend};
use servoid::model::SpecimenModel;
use servoid::model::{LinearSpecimen, RigParams};
use servoid::simulate::ode::Integrator;
use servoid::simulate::plant::{ActuatorFriction, PlantSpec, Unmodelled, simulate};

/// One run's record: the command and displacement as logged (m), its
/// specimen and P gain.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TimeRun<'a> {
    pub(crate) command_m: &'a [f64],
    pub(crate) displacement_m: &'a [f64],
    pub(crate) specimen: LinearSpecimen,
    pub(crate) p_gain: f64,
}

/// Where the fit starts, and the delay it holds.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TimeStart {
    /// The rig, a1b0 at `rig.p_gain`.
    pub(crate) rig: RigParams,
    pub(crate) piston_mass_kg: f64,
    pub(crate) friction_n: f64,
    pub(crate) smoothing_m_per_s: f64,
    /// Held: the LVDT's delay (s).
    pub(crate) delay_s: f64,
}

/// The parameters' names, in the order of [`TimeFit::values`].
pub(crate) const NAMES: [&str; 7] = [
    "beta1_per_s",
    "a1b0_n_per_m_s2",
    "a2_n_per_m",
    "a3_per_s",
    "piston_mass_kg",
    "coulomb_friction_n",
    "smoothing_velocity_m_per_s",
];

/// What the fit found.
#[derive(Debug, Clone)]
pub(crate) struct TimeFit {
    /// In the order of [`NAMES`] (a1b0 at the start's P gain).
    pub(crate) values: [f64; 7],
    /// Their standard deviations from the residuals' variance and
    /// (J^T J)^-1 (white residuals assumed: see docs/accuracy.md).
    pub(crate) stds: [f64; 7],
    /// RMS of the residuals (m), offsets and drifts removed.
    pub(crate) residual_rms_m: f64,
    pub(crate) iterations: u64,
    pub(crate) converged: bool,
    /// Simulations run (each over every run).
    pub(crate) simulations: usize,
}

/// Why the time-domain fit failed.
#[derive(Debug, thiserror::Error)]
pub(crate) enum TimeFitError {
    #[error("the time-domain fit has no runs")]
    NoRuns,
    #[error("run {run}: {command} command samples against {displacement} displacement samples")]
    Lengths {
        run: usize,
        command: usize,
        displacement: usize,
    },
    #[error("the time-domain fit's simulation failed at its start: {0}")]
    Start(String),
    #[error("the time-domain fit failed: {0}")]
    Solver(String),
}

struct Problem<'a> {
    runs: &'a [TimeRun<'a>],
    fs: f64,
    start: TimeStart,
    scale: [f64; 7],
    simulations: std::sync::atomic::AtomicUsize,
    /// The last point's residuals: the solver asks for them again with
    /// its Jacobian.
    last: std::sync::Mutex<Option<(Vec<f64>, DVector<f64>)>>,
}

impl Problem<'_> {
    fn physical(&self, theta: &[f64]) -> [f64; 7] {
        let mut p: [f64; 7] = std::array::from_fn(|i| theta[i] * self.scale[i]);
        p[6] = p[6].exp();
        p
    }

    fn spec(&self, p: &[f64; 7], run: &TimeRun) -> PlantSpec {
        let rig = RigParams {
            beta1_per_s: p[0],
            a1b0_n_per_m_s2: p[1],
            a2_n_per_m: p[2],
            a3_per_s: p[3],
            p_gain: self.start.rig.p_gain,
        }
        .at_p_gain(run.p_gain);
        plant_spec(rig, run.specimen, [p[4], p[5], p[6]])
    }

    /// Every run's residuals (logged less simulated, each run's line in
    /// time projected out), concatenated.
    fn residuals(&self, theta: &[f64]) -> Result<DVector<f64>, String> {
        if let Some((at, r)) = self.last.lock().expect("not poisoned").as_ref()
            && at == theta
        {
            return Ok(r.clone());
        }
        let r = self.simulated_residuals(theta)?;
        *self.last.lock().expect("not poisoned") = Some((theta.to_vec(), r.clone()));
        Ok(r)
    }

    fn simulated_residuals(&self, theta: &[f64]) -> Result<DVector<f64>, String> {
        self.simulations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let p = self.physical(theta);
        let mut out = Vec::new();
        for run in self.runs {
            let spec = self.spec(&p, run);
            let sim = simulate(
                &spec,
                run.command_m,
                self.fs,
                [self.start.delay_s.max(0.0), 0.0],
                Integrator::default(),
            )
            .map_err(|e| e.to_string())?;
            let r: Vec<f64> = run
                .displacement_m
                .iter()
                .zip(&sim.x1_m)
                .map(|(y, s)| y - s)
                .collect();
            out.extend(detrend(&r, Detrend::Linear));
        }
        if out.iter().any(|v| !v.is_finite()) {
            return Err("the simulation diverged".into());
        }
        Ok(DVector::from_vec(out))
    }
}

/// The plant with the piston's mass, friction and its zero-crossing width
/// `[m_p, F, v0]` (kg, N, m/s).
fn plant_spec(rig: RigParams, specimen: LinearSpecimen, piston: [f64; 3]) -> PlantSpec {
    PlantSpec {
        rig,
        specimen: specimen_model(specimen),
        unmodelled: Unmodelled {
            piston_mass_kg: Some(piston[0]),
            actuator_friction: Some(ActuatorFriction {
                coulomb_force_n: piston[1],
                smoothing_velocity_m_per_s: piston[2],
                viscous_ns_per_m: 0.0,
            }),
            ..Unmodelled::default()
        },
    }
}

fn specimen_model(s: LinearSpecimen) -> SpecimenModel {
    match s {
        LinearSpecimen::None => SpecimenModel::None,
        LinearSpecimen::Spring { stiffness_n_per_m } => SpecimenModel::Spring { stiffness_n_per_m },
        LinearSpecimen::Sdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m,
        } => SpecimenModel::LinearSdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m,
        },
    }
}

/// The solver's view of the problem, borrowed so its count of simulations
/// stays readable.
struct Borrowed<'a>(&'a Problem<'a>);

impl Operator for Borrowed<'_> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;
    fn apply(&self, theta: &DVector<f64>) -> Result<DVector<f64>, Error> {
        // A trial the simulation cannot follow is a step too far: an
        // infinite cost makes the solver reject it.
        Ok(self
            .0
            .residuals(theta.as_slice())
            .unwrap_or_else(|_| DVector::from_element(1, f64::INFINITY)))
    }
}

impl Jacobian for Borrowed<'_> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;
    fn jacobian(&self, theta: &DVector<f64>) -> Result<DMatrix<f64>, Error> {
        self.0.jacobian(theta)
    }
}

impl Problem<'_> {
    /// Forward differences of the residuals.
    fn jacobian(&self, theta: &DVector<f64>) -> Result<DMatrix<f64>, Error> {
        let r0 = self
            .residuals(theta.as_slice())
            .map_err(|e| Error::msg(format!("at an accepted point: {e}")))?;
        use rayon::prelude::*;
        let columns: Vec<DVector<f64>> = (0..theta.len())
            .into_par_iter()
            .map(|i| {
                let h = 1e-6 * theta[i].abs().max(1e-3);
                let mut t = theta.clone();
                t[i] += h;
                let r = self
                    .simulated_residuals(t.as_slice())
                    .map_err(|e| Error::msg(format!("in the Jacobian: {e}")))?;
                // Residuals are data less model: J is the residuals' own
                // derivative.
                Ok((r - &r0) / h)
            })
            .collect::<Result<_, Error>>()?;
        Ok(DMatrix::from_columns(&columns))
    }
}

/// Fits the rig, the piston's mass and its friction to the runs' logged
/// displacements (the module documentation says how).
pub(crate) fn time_domain_fit(
    runs: &[TimeRun],
    sample_rate_hz: f64,
    start: &TimeStart,
    max_iterations: u64,
) -> Result<TimeFit, TimeFitError> {
    if runs.is_empty() {
        return Err(TimeFitError::NoRuns);
    }
    for (i, r) in runs.iter().enumerate() {
        if r.command_m.len() != r.displacement_m.len() {
            return Err(TimeFitError::Lengths {
                run: i,
                command: r.command_m.len(),
                displacement: r.displacement_m.len(),
            });
        }
    }
    let p0 = [
        start.rig.beta1_per_s,
        start.rig.a1b0_n_per_m_s2,
        start.rig.a2_n_per_m,
        start.rig.a3_per_s,
        start.piston_mass_kg,
        start.friction_n,
        start.smoothing_m_per_s.ln(),
    ];
    let floors = [1.0, 1.0, 1.0, 1.0, 0.1, 1.0, 1.0];
    let scale: [f64; 7] = std::array::from_fn(|i| p0[i].abs().max(floors[i]));
    let problem = Problem {
        runs,
        fs: sample_rate_hz,
        start: *start,
        scale,
        simulations: std::sync::atomic::AtomicUsize::new(0),
        last: std::sync::Mutex::new(None),
    };
    let theta0: Vec<f64> = (0..7).map(|i| p0[i] / scale[i]).collect();
    problem.residuals(&theta0).map_err(TimeFitError::Start)?;
    // The piston's mass stays positive (the simulator needs a moving mass
    // under friction) and the friction non-negative.
    let lower = DVector::from_vec(vec![
        0.0,
        0.0,
        0.0,
        f64::NEG_INFINITY,
        0.005 / scale[4],
        0.0,
        (1e-5f64).ln() / scale[6],
    ]);
    let upper = DVector::from_vec(vec![
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        (1e-1f64).ln() / scale[6],
    ]);
    let solver = LevenbergMarquardt::new()
        .with_tolerances(1e-9, 1e-8)
        .and_then(|s| s.with_bounds(lower, upper))
        .map_err(|e| TimeFitError::Solver(e.to_string()))?;
    let result = Executor::new(Borrowed(&problem), solver)
        .configure(|s| s.param(DVector::from_vec(theta0)).max_iters(max_iterations))
        .run()
        .map_err(|e| TimeFitError::Solver(e.to_string()))?;
    let state = result.state;
    let converged = state.get_termination_reason() == Some(&TerminationReason::SolverConverged);
    let iterations = state.get_iter();
    let theta = state
        .get_best_param()
        .or(state.get_param())
        .cloned()
        .ok_or_else(|| TimeFitError::Solver("no solution".into()))?;
    let r = problem
        .residuals(theta.as_slice())
        .map_err(TimeFitError::Solver)?;
    let j = problem
        .jacobian(&theta)
        .map_err(|e| TimeFitError::Solver(e.to_string()))?;
    let n = r.len();
    // Each run's line took two degrees of freedom.
    let dof = (n - 7 - 2 * runs.len()) as f64;
    let sigma2 = r.norm_squared() / dof;
    let cov = (j.tr_mul(&j))
        .try_inverse()
        .map(|c| c * sigma2)
        .unwrap_or_else(|| DMatrix::from_element(7, 7, f64::NAN));
    let p = problem.physical(theta.as_slice());
    let stds: [f64; 7] = std::array::from_fn(|i| {
        let s = cov[(i, i)].sqrt() * scale[i];
        if i == 6 { s * p[6] } else { s }
    });
    Ok(TimeFit {
        values: p,
        stds,
        residual_rms_m: (r.norm_squared() / n as f64).sqrt(),
        iterations,
        converged,
        simulations: problem
            .simulations
            .load(std::sync::atomic::Ordering::Relaxed),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use servoid::model::PAPER_RIG;
    use servoid::simulate::Draws;

    /// A 20 s linear chirp of 4 mm from 0.2 to 20 Hz at 1 kHz, with a
    /// second at rest before and after.
    fn chirp() -> Vec<f64> {
        let fs = 1000.0;
        let (f0, f1, d) = (0.2, 20.0, 20.0);
        let mut u = vec![0.0; 1000];
        u.extend((0..(d * fs) as usize).map(|k| {
            let t = k as f64 / fs;
            0.004 * (2.0 * std::f64::consts::PI * (f0 * t + (f1 - f0) * t * t / (2.0 * d))).sin()
        }));
        u.extend(vec![0.0; 1000]);
        u
    }

    /// The paper's rig with 0.5 kg of piston and 8 N of friction
    /// (tanh(v / 2 mm/s)), a 1-sample LVDT delay, 2 um of noise, an
    /// offset and a drift: the fit from a start 3 % off (the friction 20 %)
    /// recovers every parameter within 4 of its stds, and those stds are
    /// below 1 % (the noise alone): the fit finds the optimum it is built
    /// for when started near it.
    #[test]
    fn recovers_a_rig_with_friction_from_its_simulation() {
        let truth = [267.0, 2.412e9, 7.881e5, 16.118, 0.5, 8.0, 0.002];
        let u = chirp();
        let specimens = [
            LinearSpecimen::None,
            LinearSpecimen::Spring {
                stiffness_n_per_m: 116_640.0,
            },
        ];
        let mut noise = Draws::new(7, "time-domain test");
        let logged: Vec<Vec<f64>> = specimens
            .iter()
            .map(|&specimen| {
                let spec = plant_spec(PAPER_RIG, specimen, [truth[4], truth[5], truth[6]]);
                let x = simulate(&spec, &u, 1000.0, [0.001, 0.0], Integrator::default())
                    .expect("simulates")
                    .x1_m;
                x.iter()
                    .enumerate()
                    .map(|(k, v)| v + 2e-6 * noise.normal() + 1e-4 + 1e-6 * k as f64 / 1000.0)
                    .collect()
            })
            .collect();
        let runs: Vec<TimeRun> = specimens
            .iter()
            .zip(&logged)
            .map(|(&specimen, x)| TimeRun {
                command_m: &u,
                displacement_m: x,
                specimen,
                p_gain: 1.0,
            })
            .collect();
        let start = TimeStart {
            rig: RigParams {
                beta1_per_s: truth[0] * 1.03,
                a1b0_n_per_m_s2: truth[1] * 0.97,
                a2_n_per_m: truth[2] * 1.03,
                a3_per_s: truth[3] * 0.97,
                p_gain: 1.0,
            },
            piston_mass_kg: truth[4] * 1.03,
            friction_n: truth[5] * 0.8,
            smoothing_m_per_s: 0.001,
            delay_s: 0.001,
        };
        let fit = time_domain_fit(&runs, 1000.0, &start, 40).expect("fits");
        assert!(fit.converged, "{fit:?}");
        for i in 0..7 {
            let z = (fit.values[i] - truth[i]) / fit.stds[i];
            assert!(
                z.abs() < 4.0 && fit.stds[i] < 0.01 * truth[i],
                "{}: {} against {} (std {}, {z:+.2})",
                NAMES[i],
                fit.values[i],
                truth[i],
                fit.stds[i]
            );
        }
        assert!((fit.residual_rms_m / 2e-6 - 1.0).abs() < 0.05, "{fit:?}");
    }
}
