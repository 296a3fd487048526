//! The simulator's numerical core: a rig, a test program and an instrument
//! chain in, sampled lab signals with known ground truth out.
//!
//! - [`excitation`]: command signals (chirps, multisines, band-limited noise,
//!   square waves) and the controller's command limit.
//! - [`discrete`]: exact zero-order-hold simulation of linear state spaces,
//!   with exact fractional output delays.
//! - [`ode`]: RK4 and Dormand-Prince 5(4), the input held between samples.
//! - [`specimen`]: linear, Duffing, Bouc-Wen and smoothed Coulomb friction.
//! - [`plant`]: Eq. 10 with a specimen and optional unmodelled dynamics.
//! - [`instrument`]: sensor noise, offset, drift and quantisation, with one
//!   reproducible random stream per channel.
//!
//! Pure: no files, no printing, the same bits for the same inputs. The
//! plant's equations: docs/methods.md, "The simulated plant".

pub mod discrete;
pub mod excitation;
mod fft;
pub mod instrument;
pub mod multisine;
pub mod ode;
pub mod plant;
pub mod specimen;

pub use discrete::{Discretized, simulate_linear, zoh};
pub use excitation::{
    ChirpLaw, Excitation, ExcitationError, Padding, generate, instantaneous_frequency_hz,
    time_at_frequency_s,
};
pub use instrument::{InstrumentError, Quantization, Sensor, apply, channel_rng};
pub use ode::{Integrator, OdeError, OdeSystem, simulate_held};
pub use plant::{
    ActuatorFriction, NonlinearPlant, PlantResponse, PlantSpec, Unmodelled, ValveMode,
    linear_state_space, simulate, validate,
};
pub use specimen::ForcedSpecimen;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sha2::{Digest, Sha256};

/// Why a plant cannot be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A parameter is missing its required sign or range.
    #[error(transparent)]
    Parameter(#[from] crate::model::ParameterError),
    /// The plant (or its linearisation at rest) has an eigenvalue with a
    /// non-negative real part.
    #[error(
        "the {what} is unstable: eigenvalue(s) {eigenvalues} rad/s have a non-negative real part"
    )]
    Unstable {
        /// "linear plant" or "linearisation at rest".
        what: &'static str,
        eigenvalues: String,
    },
    /// The state matrix has a non-finite entry, or its eigenvalues do not
    /// converge (finite but extreme parameters).
    #[error(
        "the {what}'s eigenvalues cannot be computed (its state matrix has an entry beyond f64's range): check the rig parameters, the specimen and the p_gain"
    )]
    NoEigenvalues {
        /// "linear plant" or "simplified canonical form".
        what: &'static str,
    },
    /// The state space handed to the linear simulator has a non-finite
    /// entry.
    #[error(
        "the model's state space has an entry beyond f64's range: check the rig parameters, the specimen and the p_gain"
    )]
    NonFiniteModel,
    /// A command sample is NaN or infinite.
    #[error("command sample {index} (t = {t_s} s) is not finite ({value})")]
    NonFiniteCommand { index: usize, t_s: f64, value: f64 },
    /// The state space handed to the linear simulator is inconsistent: A
    /// is not n x n, or B, C and D do not fit it.
    #[error(
        "state-space dimensions disagree: A is {a_rows}x{a_cols}, B has {b_rows} rows, C is {c_rows}x{c_cols}, D has {d_rows} rows"
    )]
    Dimensions {
        a_rows: usize,
        a_cols: usize,
        b_rows: usize,
        c_rows: usize,
        c_cols: usize,
        d_rows: usize,
    },
    /// The linear simulator needs one output delay per output (row of C)
    /// and was given another number.
    #[error("state-space dimensions disagree: {delays} output delay(s) for {outputs} output(s)")]
    OutputDelays { delays: usize, outputs: usize },
    /// The force reached F_max = A P_s against the valve's flow, where the
    /// servo-valve's flow-pressure law (docs/model.md) passes no flow.
    #[error(
        "the actuator force reached {force_n} N against the valve's flow near t = {t_s} s, at or beyond F_max = A P_s = {max_force_n} N, where the servo-valve passes no flow (the flow-pressure law): lower the command or the specimen's force, or raise the supply pressure or the piston area"
    )]
    BeyondSupply {
        force_n: f64,
        max_force_n: f64,
        t_s: f64,
    },
    /// The numerical integration of a nonlinear plant failed.
    #[error("integration failed: {0}")]
    Ode(#[from] OdeError),
}

/// A reproducible random stream named by a seed and a label: ChaCha8 seeded
/// with SHA-256(domain, seed, label). Different labels give independent
/// streams; the same seed and label give the same bytes on every platform.
pub fn seeded_rng(seed: u64, label: &str) -> ChaCha8Rng {
    let mut h = Sha256::new();
    h.update(b"servoid/simulate\0");
    h.update(seed.to_le_bytes());
    h.update(label.as_bytes());
    ChaCha8Rng::from_seed(h.finalize().into())
}

/// Seeded draws from a [`seeded_rng`] stream: uniforms and standard
/// normals (rand_distr's ziggurat, as the simulator's noise draws them). The
/// one generator of the simulator's noise, the unit tests' noise and the
/// benches' data, so no test carries a generator of its own.
pub struct Draws(ChaCha8Rng);

impl Draws {
    /// The stream named by `seed` and `label`.
    pub fn new(seed: u64, label: &str) -> Self {
        Self(seeded_rng(seed, label))
    }

    /// Uniform on [0, 1).
    pub fn uniform(&mut self) -> f64 {
        rand::Rng::random(&mut self.0)
    }

    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        rand::Rng::sample(&mut self.0, rand_distr::StandardNormal)
    }

    /// Circular complex Gaussian with E|z|^2 = `variance`.
    pub fn complex_normal(&mut self, variance: f64) -> nalgebra::Complex<f64> {
        let s = (0.5 * variance).sqrt();
        nalgebra::Complex::new(s * self.normal(), s * self.normal())
    }
}

pub(crate) use crate::model::specimen::{require_finite, require_non_negative, require_positive};
