//! The specimens a rig may drive (Eq. 9): their restoring forces, internal
//! states, parameter checks and linearisations at rest.
//!
//! Every specimen with mass obeys m x1'' = f_s - g(x1, x2, z), where f_s is
//! the force applied to it and g its restoring force (Eq. 9 with h = -g/m).
//! Duffing and smoothed Coulomb friction have g(x1, x2) with continuous
//! second derivatives and implement [`Specimen`], so the controllable
//! canonical form (Eqs. 34-35) applies to them; Bouc-Wen carries its
//! hysteretic state z and cannot.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{LinearSdof, LinearSpecimen, Specimen};

/// A parameter without its required sign or range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{owner}: {name} must be {requirement} (got {value})")]
pub struct ParameterError {
    /// Which part of the plant (e.g. "rig", "duffing specimen").
    pub owner: &'static str,
    /// The parameter's name, as in the types of this module.
    pub name: &'static str,
    pub value: f64,
    pub requirement: &'static str,
}

/// Checks that `value` is finite and positive.
pub(crate) fn require_positive(
    owner: &'static str,
    name: &'static str,
    value: f64,
) -> Result<(), ParameterError> {
    require(
        value.is_finite() && value > 0.0,
        owner,
        name,
        value,
        "positive and finite",
    )
}

/// Checks that `value` is finite and non-negative.
pub(crate) fn require_non_negative(
    owner: &'static str,
    name: &'static str,
    value: f64,
) -> Result<(), ParameterError> {
    require(
        value.is_finite() && value >= 0.0,
        owner,
        name,
        value,
        "non-negative and finite",
    )
}

/// Checks that `value` is finite.
pub(crate) fn require_finite(
    owner: &'static str,
    name: &'static str,
    value: f64,
) -> Result<(), ParameterError> {
    require(value.is_finite(), owner, name, value, "finite")
}

fn require(
    holds: bool,
    owner: &'static str,
    name: &'static str,
    value: f64,
    requirement: &'static str,
) -> Result<(), ParameterError> {
    if holds {
        Ok(())
    } else {
        Err(ParameterError {
            owner,
            name,
            value,
            requirement,
        })
    }
}

/// Cubic-stiffness (Duffing) specimen: g = c x2 + k x1 + k3 x1^3.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Duffing {
    pub mass_kg: f64,
    pub damping_ns_per_m: f64,
    pub stiffness_n_per_m: f64,
    /// k3 (N/m^3): hardening when positive, softening when negative.
    pub cubic_stiffness_n_per_m3: f64,
}

/// Bouc-Wen hysteretic specimen in Wen's form (Wen 1976, "Method for random
/// vibration of hysteretic systems", J. Eng. Mech. Div. ASCE 102:249-263;
/// notation of Ismail, Ikhouane & Rodellar 2009, "The hysteresis Bouc-Wen
/// model, a survey", Arch. Comput. Methods Eng. 16:161-188):
///
/// g = c x2 + alpha k x1 + (1 - alpha) k z,
/// z' = A x2 - beta |x2| |z|^(n-1) z - gamma x2 |z|^n,
///
/// with z a displacement (m), k the initial elastic stiffness (dg/dx1 = k at
/// z = 0 when A = 1) and alpha the ratio of post- to pre-yield stiffness.
/// With A > 0, beta > 0 and |gamma| <= beta, z stays within
/// (A / (beta + gamma))^(1/n) and the loop dissipates energy (Ikhouane,
/// Manosa & Rodellar 2007, Systems & Control Letters 56:197-205).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct BoucWen {
    pub mass_kg: f64,
    pub damping_ns_per_m: f64,
    /// k (N/m), the initial elastic stiffness.
    pub stiffness_n_per_m: f64,
    /// alpha in [0, 1]: post- to pre-yield stiffness ratio.
    pub alpha: f64,
    /// A (dimensionless), the initial slope dz/dx1.
    pub a: f64,
    /// beta (1/m^n).
    pub beta_per_m_pow_n: f64,
    /// gamma (1/m^n).
    pub gamma_per_m_pow_n: f64,
    /// n >= 1: sharpness of the elastic-plastic transition.
    pub n: f64,
}

/// Viscous spring-mass specimen with smoothed Coulomb friction:
/// g = c x2 + k x1 + f_c tanh(x2 / v_s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Friction {
    pub mass_kg: f64,
    pub damping_ns_per_m: f64,
    pub stiffness_n_per_m: f64,
    /// f_c (N), the sliding friction force.
    pub coulomb_force_n: f64,
    /// v_s (m/s): tanh smoothing; the friction force reaches 76 % of f_c at v_s.
    pub smoothing_velocity_m_per_s: f64,
}

/// The specimen attached to the actuator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SpecimenModel {
    /// Nothing attached.
    None,
    /// A massless linear spring, g = k x1.
    Spring {
        stiffness_n_per_m: f64,
    },
    /// m x1'' + c x1' + k x1 = f (Eq. 15).
    LinearSdof {
        mass_kg: f64,
        damping_ns_per_m: f64,
        stiffness_n_per_m: f64,
    },
    Duffing(Duffing),
    BoucWen(BoucWen),
    Friction(Friction),
}

impl SpecimenModel {
    /// A short name for messages.
    pub fn name(&self) -> &'static str {
        match self {
            SpecimenModel::None => "no specimen",
            SpecimenModel::Spring { .. } => "spring specimen",
            SpecimenModel::LinearSdof { .. } => "linear sdof specimen",
            SpecimenModel::Duffing(_) => "duffing specimen",
            SpecimenModel::BoucWen(_) => "bouc-wen specimen",
            SpecimenModel::Friction(_) => "friction specimen",
        }
    }

    /// Checks every parameter's sign and range. Stiffness may be negative
    /// (negative-stiffness devices exist; whether the closed loop stays stable
    /// is the plant's eigenvalue check), except Bouc-Wen's k, which scales
    /// its hysteretic force.
    pub fn validate(&self) -> Result<(), ParameterError> {
        let who = self.name();
        match *self {
            SpecimenModel::None => {}
            SpecimenModel::Spring { stiffness_n_per_m } => {
                require_finite(who, "stiffness_n_per_m", stiffness_n_per_m)?;
            }
            SpecimenModel::LinearSdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            } => {
                require_positive(who, "mass_kg", mass_kg)?;
                require_non_negative(who, "damping_ns_per_m", damping_ns_per_m)?;
                require_finite(who, "stiffness_n_per_m", stiffness_n_per_m)?;
            }
            // A massless Duffing spring (mass and damping zero) is a spring
            // run's specimen that is not quite linear; with a mass it is an
            // SDOF specimen.
            SpecimenModel::Duffing(d) if d.mass_kg == 0.0 && d.damping_ns_per_m == 0.0 => {
                require_finite(who, "stiffness_n_per_m", d.stiffness_n_per_m)?;
                require_finite(who, "cubic_stiffness_n_per_m3", d.cubic_stiffness_n_per_m3)?;
            }
            SpecimenModel::Duffing(d) => {
                require_positive(who, "mass_kg", d.mass_kg)?;
                require_non_negative(who, "damping_ns_per_m", d.damping_ns_per_m)?;
                require_finite(who, "stiffness_n_per_m", d.stiffness_n_per_m)?;
                require_finite(who, "cubic_stiffness_n_per_m3", d.cubic_stiffness_n_per_m3)?;
            }
            SpecimenModel::Friction(f) => {
                require_positive(who, "mass_kg", f.mass_kg)?;
                require_non_negative(who, "damping_ns_per_m", f.damping_ns_per_m)?;
                require_finite(who, "stiffness_n_per_m", f.stiffness_n_per_m)?;
                require_non_negative(who, "coulomb_force_n", f.coulomb_force_n)?;
                require_positive(
                    who,
                    "smoothing_velocity_m_per_s",
                    f.smoothing_velocity_m_per_s,
                )?;
            }
            SpecimenModel::BoucWen(b) => {
                require_positive(who, "mass_kg", b.mass_kg)?;
                require_non_negative(who, "damping_ns_per_m", b.damping_ns_per_m)?;
                require_positive(who, "stiffness_n_per_m", b.stiffness_n_per_m)?;
                if !(0.0..=1.0).contains(&b.alpha) {
                    return Err(ParameterError {
                        owner: who,
                        name: "alpha",
                        value: b.alpha,
                        requirement: "in [0, 1]",
                    });
                }
                require_positive(who, "a", b.a)?;
                require_positive(who, "beta_per_m_pow_n", b.beta_per_m_pow_n)?;
                require_finite(who, "gamma_per_m_pow_n", b.gamma_per_m_pow_n)?;
                if b.gamma_per_m_pow_n.abs() > b.beta_per_m_pow_n {
                    return Err(ParameterError {
                        owner: who,
                        name: "gamma_per_m_pow_n",
                        value: b.gamma_per_m_pow_n,
                        requirement: "within [-beta_per_m_pow_n, beta_per_m_pow_n] (bounded, dissipative Bouc-Wen)",
                    });
                }
                if !(b.n.is_finite() && b.n >= 1.0) {
                    return Err(ParameterError {
                        owner: who,
                        name: "n",
                        value: b.n,
                        requirement: "finite and at least 1",
                    });
                }
            }
        }
        Ok(())
    }

    /// The specimen's own mass (kg); zero without a specimen or for a spring.
    pub fn mass_kg(&self) -> f64 {
        match *self {
            SpecimenModel::None | SpecimenModel::Spring { .. } => 0.0,
            SpecimenModel::LinearSdof { mass_kg, .. } => mass_kg,
            SpecimenModel::Duffing(d) => d.mass_kg,
            SpecimenModel::BoucWen(b) => b.mass_kg,
            SpecimenModel::Friction(f) => f.mass_kg,
        }
    }

    /// (m, c, k) of a linear specimen; `None` for the nonlinear ones.
    pub fn linear_mck(&self) -> Option<(f64, f64, f64)> {
        match *self {
            SpecimenModel::None => Some((0.0, 0.0, 0.0)),
            SpecimenModel::Spring { stiffness_n_per_m } => Some((0.0, 0.0, stiffness_n_per_m)),
            SpecimenModel::LinearSdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            } => Some((mass_kg, damping_ns_per_m, stiffness_n_per_m)),
            _ => None,
        }
    }

    /// The paper's linear specimen (Eq. 10 with h linear), when this is one.
    pub fn linear(&self) -> Option<LinearSpecimen> {
        use LinearSpecimen as L;
        match *self {
            SpecimenModel::None => Some(L::None),
            SpecimenModel::Spring { stiffness_n_per_m } => Some(L::Spring { stiffness_n_per_m }),
            SpecimenModel::LinearSdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            } => Some(L::Sdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            }),
            _ => None,
        }
    }

    /// Undamped natural frequency sqrt(k/m)/(2 pi) (Hz) of the linearisation
    /// at rest, for a specimen with mass and positive stiffness.
    pub fn natural_frequency_hz(&self) -> Option<f64> {
        let (m, _, k) = self.linearised_at_rest();
        (m > 0.0 && k > 0.0).then(|| (k / m).sqrt() / (2.0 * std::f64::consts::PI))
    }

    /// (m, c, k) of the linearisation at rest (x1 = x2 = z = 0). Friction's
    /// tanh adds f_c / v_s of damping. Bouc-Wen's z' = A x2 makes z = A x1
    /// along motions from rest (its other mode, z - A x1 = constant, is a
    /// neutral integrator), so its stiffness is alpha k + (1 - alpha) k A.
    pub fn linearised_at_rest(&self) -> (f64, f64, f64) {
        if let Some(mck) = self.linear_mck() {
            return mck;
        }
        match *self {
            SpecimenModel::Duffing(d) => (d.mass_kg, d.damping_ns_per_m, d.stiffness_n_per_m),
            SpecimenModel::Friction(f) => (
                f.mass_kg,
                f.damping_ns_per_m + f.coulomb_force_n / f.smoothing_velocity_m_per_s,
                f.stiffness_n_per_m,
            ),
            SpecimenModel::BoucWen(b) => (
                b.mass_kg,
                b.damping_ns_per_m,
                b.alpha * b.stiffness_n_per_m + (1.0 - b.alpha) * b.stiffness_n_per_m * b.a,
            ),
            _ => unreachable!("linear specimens returned above"),
        }
    }

    /// Whether the specimen puts any force on the actuator (a mass, a
    /// damper or a spring: at rest or linearised there).
    pub fn loads(&self) -> bool {
        let (m, c, k) = self.linearised_at_rest();
        m != 0.0 || c != 0.0 || k != 0.0
    }

    /// Number of internal states (Bouc-Wen's z).
    pub fn internal_states(&self) -> usize {
        match self {
            SpecimenModel::BoucWen(_) => 1,
            _ => 0,
        }
    }

    /// The restoring force g (N) at displacement x1 (m), velocity x2 (m/s)
    /// and internal state `z` (`internal_states()` values).
    pub fn restoring_force_n(&self, x1: f64, x2: f64, z: &[f64]) -> f64 {
        match *self {
            SpecimenModel::None => 0.0,
            SpecimenModel::Spring { stiffness_n_per_m } => stiffness_n_per_m * x1,
            SpecimenModel::LinearSdof {
                damping_ns_per_m,
                stiffness_n_per_m,
                ..
            } => damping_ns_per_m * x2 + stiffness_n_per_m * x1,
            SpecimenModel::Duffing(d) => {
                d.damping_ns_per_m * x2
                    + d.stiffness_n_per_m * x1
                    + d.cubic_stiffness_n_per_m3 * x1 * x1 * x1
            }
            SpecimenModel::Friction(f) => {
                f.damping_ns_per_m * x2
                    + f.stiffness_n_per_m * x1
                    + f.coulomb_force_n * (x2 / f.smoothing_velocity_m_per_s).tanh()
            }
            SpecimenModel::BoucWen(b) => {
                b.damping_ns_per_m * x2
                    + b.alpha * b.stiffness_n_per_m * x1
                    + (1.0 - b.alpha) * b.stiffness_n_per_m * z[0]
            }
        }
    }

    /// dg/dx1 of a spring whose force depends on x1 alone (a massless
    /// specimen: none, a spring, a massless Duffing spring); None otherwise.
    pub fn spring_slope_n_per_m(&self, x1: f64) -> Option<f64> {
        match *self {
            SpecimenModel::None => Some(0.0),
            SpecimenModel::Spring { stiffness_n_per_m } => Some(stiffness_n_per_m),
            SpecimenModel::Duffing(d) if d.mass_kg == 0.0 && d.damping_ns_per_m == 0.0 => {
                Some(d.stiffness_n_per_m + 3.0 * d.cubic_stiffness_n_per_m3 * x1 * x1)
            }
            _ => None,
        }
    }

    /// Writes the internal states' rates at velocity x2 into `dz`.
    pub fn internal_rates(&self, x2: f64, z: &[f64], dz: &mut [f64]) {
        if let SpecimenModel::BoucWen(b) = *self {
            dz[0] = b.z_rate(x2, z[0]);
        }
    }

    /// The specimen as h(x1, x2) of Eq. 9 for the controllable canonical
    /// form, when it has a mass and no internal state.
    pub fn as_specimen(&self) -> Option<Box<dyn Specimen>> {
        match *self {
            SpecimenModel::LinearSdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            } => Some(Box::new(LinearSdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            })),
            SpecimenModel::Duffing(d) => Some(Box::new(d)),
            SpecimenModel::Friction(f) => Some(Box::new(f)),
            _ => None,
        }
    }
}

impl BoucWen {
    /// z' = A x2 - beta |x2| |z|^(n-1) z - gamma x2 |z|^n.
    pub fn z_rate(&self, x2: f64, z: f64) -> f64 {
        let (zn1_z, zn) = if self.n == 1.0 {
            (z, z.abs())
        } else {
            let p = z.abs().powf(self.n - 1.0);
            (p * z, p * z.abs())
        };
        self.a * x2 - self.beta_per_m_pow_n * x2.abs() * zn1_z - self.gamma_per_m_pow_n * x2 * zn
    }
}

impl Specimen for Duffing {
    fn mass_kg(&self) -> f64 {
        self.mass_kg
    }
    fn h(&self, x1: f64, x2: f64) -> f64 {
        -(self.damping_ns_per_m * x2
            + self.stiffness_n_per_m * x1
            + self.cubic_stiffness_n_per_m3 * x1 * x1 * x1)
            / self.mass_kg
    }
    fn grad_h(&self, x1: f64, _x2: f64) -> [f64; 2] {
        [
            -(self.stiffness_n_per_m + 3.0 * self.cubic_stiffness_n_per_m3 * x1 * x1)
                / self.mass_kg,
            -self.damping_ns_per_m / self.mass_kg,
        ]
    }
    fn hess_h(&self, x1: f64, _x2: f64) -> [f64; 3] {
        [
            -6.0 * self.cubic_stiffness_n_per_m3 * x1 / self.mass_kg,
            0.0,
            0.0,
        ]
    }
}

impl Specimen for Friction {
    fn mass_kg(&self) -> f64 {
        self.mass_kg
    }
    fn h(&self, x1: f64, x2: f64) -> f64 {
        -(self.damping_ns_per_m * x2
            + self.stiffness_n_per_m * x1
            + self.coulomb_force_n * (x2 / self.smoothing_velocity_m_per_s).tanh())
            / self.mass_kg
    }
    fn grad_h(&self, _x1: f64, x2: f64) -> [f64; 2] {
        let vs = self.smoothing_velocity_m_per_s;
        let sech2 = 1.0 - (x2 / vs).tanh().powi(2);
        [
            -self.stiffness_n_per_m / self.mass_kg,
            -(self.damping_ns_per_m + self.coulomb_force_n * sech2 / vs) / self.mass_kg,
        ]
    }
    fn hess_h(&self, _x1: f64, x2: f64) -> [f64; 3] {
        // d2/dv2 tanh(v / vs) = -2 sech^2(v / vs) tanh(v / vs) / vs^2.
        let vs = self.smoothing_velocity_m_per_s;
        let th = (x2 / vs).tanh();
        let sech2 = 1.0 - th * th;
        [
            0.0,
            2.0 * self.coulomb_force_n * sech2 * th / (vs * vs * self.mass_kg),
            0.0,
        ]
    }
}
