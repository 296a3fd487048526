//! The plant of Maghareh, Silva & Dyke (2018): servo-valve, actuator with
//! natural velocity feedback and P controller (the hydraulic transfer system)
//! coupled to a specimen. Owns the state space of Eq. 10, the transfer
//! functions of Eqs. 11-17 and 45, and the controllable canonical form of
//! Eqs. 34-35, with the signs checked (docs/model.md).
//!
//! Units are SI throughout: x1 (m), x2 [m/s], f (N), r [N/s], u (m).

use nalgebra::{Complex, DMatrix, DVector};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::lti::{LtiError, StateSpace, TransferFunction};

pub mod flow;
pub mod specimen;
pub use specimen::{BoucWen, Duffing, Friction, ParameterError, SpecimenModel};

/// The four parameters of the hydraulic transfer system (Eq. 10), with a1b0
/// stated at the P gain `p_gain` (a1b0 = a1 P c is proportional to P, Eq. 7).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct RigParams {
    /// Servo-valve pole beta1 [1/s] (time constant 1/beta1).
    pub beta1_per_s: f64,
    /// a1 b0 [N/(m s^2)] at the P gain `p_gain`.
    pub a1b0_n_per_m_s2: f64,
    /// a2 [N/m] (2 beta A^2 / V, Eq. 4).
    pub a2_n_per_m: f64,
    /// a3 [1/s] (2 beta Kc / V, Eq. 4).
    pub a3_per_s: f64,
    /// The P gain at which `a1b0_n_per_m_s2` holds.
    #[serde(default = "unit_gain")]
    pub p_gain: f64,
}

/// The paper's mean identified rig (Sec. 3.1, Table 3), a1b0 at P = 1: the
/// rig the bundled campaigns, tests and benchmarks are built on.
pub const PAPER_RIG: RigParams = RigParams {
    beta1_per_s: 267.0,
    a1b0_n_per_m_s2: 2.412e9,
    a2_n_per_m: 7.881e5,
    a3_per_s: 16.118,
    p_gain: 1.0,
};

fn unit_gain() -> f64 {
    1.0
}

impl RigParams {
    /// The same rig at another P gain: a1b0 scales linearly, nothing else
    /// changes (Eq. 7; paper Sec. 3.2).
    pub fn at_p_gain(&self, p_gain: f64) -> RigParams {
        RigParams {
            a1b0_n_per_m_s2: self.a1b0_n_per_m_s2 * p_gain / self.p_gain,
            p_gain,
            ..*self
        }
    }

    /// R1 = a1b0 / a2 [1/s^2] (Eq. 18) at this P gain.
    pub fn r1(&self) -> f64 {
        self.a1b0_n_per_m_s2 / self.a2_n_per_m
    }

    /// True when every parameter is finite and positive.
    pub fn is_physical(&self) -> bool {
        [
            self.beta1_per_s,
            self.a1b0_n_per_m_s2,
            self.a2_n_per_m,
            self.a3_per_s,
            self.p_gain,
        ]
        .iter()
        .all(|v| v.is_finite() && *v > 0.0)
    }
}

/// A linear specimen. The paper's identification assumes the piston mass is
/// negligible, so without a specimen mass the rig is massless and f = k x1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LinearSpecimen {
    /// Nothing attached (f = 0).
    None,
    /// A massless linear spring, f = k x1.
    Spring { stiffness_n_per_m: f64 },
    /// A linear single-degree-of-freedom specimen, m x1'' + c x1' + k x1 = f (Eq. 15).
    Sdof {
        mass_kg: f64,
        damping_ns_per_m: f64,
        stiffness_n_per_m: f64,
    },
}

impl LinearSpecimen {
    /// (m, c, k) of the specimen polynomial m s^2 + c s + k: zero mass and
    /// damping for a massless spring, all zero without a specimen.
    pub fn mck(&self) -> (f64, f64, f64) {
        match *self {
            LinearSpecimen::None => (0.0, 0.0, 0.0),
            LinearSpecimen::Spring { stiffness_n_per_m } => (0.0, 0.0, stiffness_n_per_m),
            LinearSpecimen::Sdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            } => (mass_kg, damping_ns_per_m, stiffness_n_per_m),
        }
    }

    /// Undamped natural frequency sqrt(k/m)/(2 pi) (Hz) of an SDOF specimen.
    pub fn natural_frequency_hz(&self) -> Option<f64> {
        match *self {
            LinearSpecimen::Sdof {
                mass_kg,
                stiffness_n_per_m,
                ..
            } => Some((stiffness_n_per_m / mass_kg).sqrt() / (2.0 * std::f64::consts::PI)),
            _ => None,
        }
    }
}

/// Output rows of [`state_space`].
pub const OUT_X1: usize = 0;
pub const OUT_FORCE: usize = 1;

/// The plant of Eq. 10 as a state space with outputs [x1, f].
///
/// SDOF: states [x1, x2, f, r]. Massless cases (no specimen, spring): the x2
/// row disappears and f = k x1, so f' = k x1' and the force row solves for
/// x1' = (r - a3 k x1) / (k + a2); states [x1, r].
pub fn state_space(rig: &RigParams, specimen: &LinearSpecimen) -> StateSpace {
    let (b1, a1b0, a2, a3) = (
        rig.beta1_per_s,
        rig.a1b0_n_per_m_s2,
        rig.a2_n_per_m,
        rig.a3_per_s,
    );
    match *specimen {
        LinearSpecimen::None | LinearSpecimen::Spring { .. } => {
            let k = match *specimen {
                LinearSpecimen::Spring { stiffness_n_per_m } => stiffness_n_per_m,
                _ => 0.0,
            };
            let a =
                DMatrix::from_row_slice(2, 2, &[-a3 * k / (k + a2), 1.0 / (k + a2), -a1b0, -b1]);
            let b = DVector::from_vec(vec![0.0, a1b0]);
            let c = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, k, 0.0]);
            StateSpace {
                a,
                b,
                c,
                d: DVector::zeros(2),
            }
        }
        LinearSpecimen::Sdof {
            mass_kg: m,
            damping_ns_per_m: c,
            stiffness_n_per_m: k,
        } => {
            #[rustfmt::skip]
            let a = DMatrix::from_row_slice(4, 4, &[
                0.0,    1.0,    0.0,     0.0,
                -k / m, -c / m, 1.0 / m, 0.0,
                0.0,    -a2,    -a3,     1.0,
                -a1b0,  0.0,    0.0,     -b1,
            ]);
            let b = DVector::from_vec(vec![0.0, 0.0, 0.0, a1b0]);
            #[rustfmt::skip]
            let cm = DMatrix::from_row_slice(2, 4, &[
                1.0, 0.0, 0.0, 0.0,
                0.0, 0.0, 1.0, 0.0,
            ]);
            StateSpace {
                a,
                b,
                c: cm,
                d: DVector::zeros(2),
            }
        }
    }
}

/// x1/u from the paper's closed forms: Eq. 12 (no specimen), Eq. 14 (spring),
/// Eq. 17 (linear SDOF), normalised to `den[0] = 1`.
///
/// An error when a coefficient leaves f64's range: finite but extreme
/// inputs (a specimen mass of 1e-300 kg, a stiffness of 1e300 N/m, a rig
/// fitted from such published coefficients) overflow the products of Eqs.
/// 12-17. The caller names the run and its keys.
pub fn tf_x1_u(rig: &RigParams, specimen: &LinearSpecimen) -> Result<TransferFunction, LtiError> {
    let (b1, a1b0, a2, a3) = (
        rig.beta1_per_s,
        rig.a1b0_n_per_m_s2,
        rig.a2_n_per_m,
        rig.a3_per_s,
    );
    let n0 = a1b0;
    let den: Vec<f64> = match *specimen {
        // Eq. 12
        LinearSpecimen::None => vec![a2, b1 * a2, a1b0],
        // Eq. 14
        LinearSpecimen::Spring {
            stiffness_n_per_m: k,
        } => vec![k + a2, a3 * k + b1 * k + b1 * a2, b1 * a3 * k + a1b0],
        // Eq. 17
        LinearSpecimen::Sdof {
            mass_kg: m,
            damping_ns_per_m: c,
            stiffness_n_per_m: k,
        } => vec![
            m,
            a3 * m + c + b1 * m,
            k + a3 * c + a2 + b1 * a3 * m + b1 * c,
            a3 * k + b1 * k + b1 * a3 * c + b1 * a2,
            b1 * a3 * k + a1b0,
        ],
    };
    TransferFunction::new(&[n0], &den)
}

/// What the joint fit finds beyond Eq. 10's four parameters that a
/// validation run's prediction carries: the piston seals' Coulomb friction
/// and, where the data resolve it, the piston's mass.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Seals {
    /// F (N): the friction force while the piston slides.
    pub coulomb_friction_n: f64,
    /// m_p (kg), when the chosen structure fits it.
    pub piston_mass_kg: Option<f64>,
    /// The friction's zero-crossing width v0 (m/s), when the manifest
    /// states it (`identification.joint.friction_smoothing_m_per_s`).
    pub smoothing_velocity_m_per_s: Option<f64>,
    /// The seals' viscous damping c_v (N s/m), when the data took it.
    pub seal_damping_ns_per_m: Option<f64>,
}

/// Everything beyond Eq. 10's rig that a validation run's prediction
/// carries, as the joint fit found it: the seals' friction and the
/// servo-valve's flow-pressure law (docs/model.md).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RigExtras {
    pub seals: Option<Seals>,
    /// F_max = A P_s (N) of the flow-pressure law, fitted or, where the
    /// runs do not determine it, the nameplate's.
    pub max_force_n: Option<f64>,
}

/// v0 of the seals' friction F tanh(x2 / v0) a prediction simulates where
/// the manifest states none. The describing function the joint fit then
/// uses holds a sign function, which an ODE solver cannot step across;
/// 1 mm/s rounds it off below the velocities a sweep reaches over nearly
/// all of its band (4 mm at 1 Hz is 25 mm/s), where its force is then
/// within 0.5 % of F sign(x2) (tanh(3) = 0.995).
pub const SEAL_SMOOTHING_M_PER_S: f64 = 1e-3;

impl Seals {
    /// v0 (m/s): the stated width, else [`SEAL_SMOOTHING_M_PER_S`].
    pub fn smoothing(&self) -> f64 {
        self.smoothing_velocity_m_per_s
            .unwrap_or(SEAL_SMOOTHING_M_PER_S)
    }
}

/// The describing function of F tanh(v / v0) over that of F sign(v), at
/// velocity amplitude V = `ratio` v0: the fundamental of tanh(r sin t)
/// against sin t, g(r) = (1/2) int_0^pi tanh(r sin t) sin t dt, which
/// tends to 1 as r grows. Simpson's rule over [0, pi/2] (the integrand is
/// symmetric about pi/2) where r < 20; beyond, 1 - pi^2 / (24 r^2), the
/// leading term of the deficit (int_0^inf (1 - tanh u) u du = pi^2 / 24),
/// within 1e-5 there.
pub fn tanh_friction_gain(ratio: f64) -> f64 {
    if ratio.is_nan() || ratio <= 0.0 {
        return 0.0;
    }
    if ratio >= 20.0 {
        return 1.0 - std::f64::consts::PI.powi(2) / (24.0 * ratio * ratio);
    }
    const N: usize = 128;
    let h = std::f64::consts::FRAC_PI_2 / N as f64;
    let f = |t: f64| (ratio * t.sin()).tanh() * t.sin();
    let inner: f64 = (1..N)
        .map(|k| if k % 2 == 1 { 4.0 } else { 2.0 } * f(k as f64 * h))
        .sum();
    // (1/2) * 2 * int_0^{pi/2}.
    (f(0.0) + inner + f(std::f64::consts::FRAC_PI_2)) * h / 3.0
}

/// Coulomb friction's describing function per newton of F, as the load it
/// adds to the piston's S(s) at `f_hz` (imaginary: a damper) where the
/// piston moves with displacement amplitude X = `amplitude_m`: 4 / (pi X)
/// for F sign(x1'), times [`tanh_friction_gain`] at V = w X for
/// F tanh(x1' / v0) with the width `smoothing_m_per_s` stated.
pub fn coulomb_load_per_newton(f_hz: f64, amplitude_m: f64, smoothing_m_per_s: Option<f64>) -> f64 {
    let w = 2.0 * std::f64::consts::PI * f_hz;
    let gain = smoothing_m_per_s.map_or(1.0, |v0| tanh_friction_gain(w * amplitude_m / v0));
    4.0 * gain / (std::f64::consts::PI * amplitude_m)
}

/// The factor the seals' friction puts on x1/u at `f_hz` where the piston
/// moves with displacement amplitude `amplitude_m`. Its describing function
/// ([`coulomb_load_per_newton`] times F, j) and its viscous part c_v s
/// add to the specimen's S(s) = m s^2 + c s + k (docs/model.md), so with
/// D = (s + beta1)((s + a3) S + a2 s) + a1b0, the denominator of Eqs.
/// 12-17, x1/u = a1b0 / D becomes a1b0 / (D + (s + beta1)(s + a3) L),
/// L = j F N + c_v s with N that load per newton: the factor is D over
/// that. Its Coulomb part tends to 1 as X grows and the friction weighs
/// less.
pub fn friction_factor(
    rig: &RigParams,
    specimen: &LinearSpecimen,
    seals: &Seals,
    amplitude_m: f64,
    f_hz: f64,
) -> Complex<f64> {
    let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f_hz);
    let (m, c, k) = specimen.mck();
    let sp = s * s * m + s * c + k;
    let (b1, a3) = (rig.beta1_per_s, rig.a3_per_s);
    let d = (s + b1) * ((s + a3) * sp + s * rig.a2_n_per_m) + rig.a1b0_n_per_m_s2;
    let friction = Complex::new(
        0.0,
        seals.coulomb_friction_n
            * coulomb_load_per_newton(f_hz, amplitude_m, seals.smoothing_velocity_m_per_s),
    ) + s * seals.seal_damping_ns_per_m.unwrap_or(0.0);
    d / (d + (s + b1) * (s + a3) * friction)
}

/// f/u: a1b0 (m s^2 + c s + k) over the x1/u denominator (Eq. 45); for a
/// massless spring f = k x1, and without a specimen f = 0.
pub fn tf_f_u(rig: &RigParams, specimen: &LinearSpecimen) -> Result<TransferFunction, LtiError> {
    let x = tf_x1_u(rig, specimen)?;
    let (m, c, k) = specimen.mck();
    let num = crate::poly::mul(&x.num, &[m, c, k]);
    TransferFunction::new(&num, &x.den)
}

/// The standard deviations of x1/u (Eq. 17, with `specimen`) in dB and
/// rad at `freq_hz` when the rig's (beta1, a1b0, a2, a3) have covariance
/// `cov` (a1b0 at `rig.p_gain`): first-order propagation, g' C g with g
/// the gradient of 20 log10 |G| or arg G, by central differences of ln G
/// (steps of 1e-6 of each parameter). None when a perturbed model leaves
/// f64's range.
pub fn x1_u_std(
    rig: &RigParams,
    cov: &[[f64; 4]; 4],
    specimen: &LinearSpecimen,
    freq_hz: &[f64],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let theta = [
        rig.beta1_per_s,
        rig.a1b0_n_per_m_s2,
        rig.a2_n_per_m,
        rig.a3_per_s,
    ];
    let with = |i: usize, h: f64| {
        let mut t = theta;
        t[i] += h;
        tf_x1_u(
            &RigParams {
                beta1_per_s: t[0],
                a1b0_n_per_m_s2: t[1],
                a2_n_per_m: t[2],
                a3_per_s: t[3],
                p_gain: rig.p_gain,
            },
            specimen,
        )
    };
    let steps: [f64; 4] = std::array::from_fn(|i| 1e-6 * theta[i].abs().max(1e-12));
    let plus: Vec<TransferFunction> = (0..4)
        .map(|i| with(i, steps[i]))
        .collect::<Result<_, _>>()
        .ok()?;
    let minus: Vec<TransferFunction> = (0..4)
        .map(|i| with(i, -steps[i]))
        .collect::<Result<_, _>>()
        .ok()?;
    let bands = freq_hz
        .iter()
        .map(|&f| {
            // d ln G / d theta_i; ln of a ratio keeps the phase unwrapped.
            let g: [Complex<f64>; 4] = std::array::from_fn(|i| {
                (plus[i].freq_response(f) / minus[i].freq_response(f)).ln() / (2.0 * steps[i])
            });
            crate::lti::log_response_std(&g, |i, j| cov[i][j])
        })
        .unzip();
    Some(bands)
}

/// A specimen in the generalised form of Eq. 9: x1'' = h(x1, x2) + f/m.
///
/// The controllable canonical form needs h's first and second partial
/// derivatives (Eqs. 29, 31, 35); a nonlinear specimen implements this trait.
pub trait Specimen {
    /// Specimen mass m (kg).
    fn mass_kg(&self) -> f64;
    /// h(x1, x2) [m/s^2].
    fn h(&self, x1: f64, x2: f64) -> f64;
    /// [dh/dx1, dh/dx2].
    fn grad_h(&self, x1: f64, x2: f64) -> [f64; 2];
    /// [d2h/dx1^2, d2h/dx2^2, d2h/dx1dx2].
    fn hess_h(&self, x1: f64, x2: f64) -> [f64; 3];
}

/// A linear SDOF specimen as h = -(k/m) x1 - (c/m) x2 (Eq. 15).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearSdof {
    pub mass_kg: f64,
    pub damping_ns_per_m: f64,
    pub stiffness_n_per_m: f64,
}

impl Specimen for LinearSdof {
    fn mass_kg(&self) -> f64 {
        self.mass_kg
    }
    fn h(&self, x1: f64, x2: f64) -> f64 {
        -(self.stiffness_n_per_m * x1 + self.damping_ns_per_m * x2) / self.mass_kg
    }
    fn grad_h(&self, _x1: f64, _x2: f64) -> [f64; 2] {
        [
            -self.stiffness_n_per_m / self.mass_kg,
            -self.damping_ns_per_m / self.mass_kg,
        ]
    }
    fn hess_h(&self, _x1: f64, _x2: f64) -> [f64; 3] {
        [0.0, 0.0, 0.0]
    }
}

/// The coefficients C1-C5 of the controllable canonical form (Eq. 35, signs of
/// docs/model.md): x4' = C1 u - C1 x1 + C2 x2 + C3 x3 + C4 x4 + C5 f + Cn.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[allow(non_snake_case)]
pub struct CcfCoefficients {
    /// C1 = a1b0/m [1/s^4].
    pub C1: f64,
    /// C2 = -beta1 a2/m + (beta1 + a3) dh/dx1 [1/s^3].
    pub C2: f64,
    /// C3 = (beta1 + a3) dh/dx2 - a2/m [1/s^2].
    pub C3: f64,
    /// C4 = -(beta1 + a3) [1/s].
    pub C4: f64,
    /// C5 = -beta1 a3/m [1/(kg s^2)].
    pub C5: f64,
}

/// C1-C5 at the state (x1, x2); for a linear specimen they do not depend on it.
pub fn ccf_coefficients<S: Specimen + ?Sized>(
    rig: &RigParams,
    specimen: &S,
    x1: f64,
    x2: f64,
) -> CcfCoefficients {
    let (b1, a1b0, a2, a3) = (
        rig.beta1_per_s,
        rig.a1b0_n_per_m_s2,
        rig.a2_n_per_m,
        rig.a3_per_s,
    );
    let m = specimen.mass_kg();
    let [h1, h2] = specimen.grad_h(x1, x2);
    CcfCoefficients {
        C1: a1b0 / m,
        C2: -b1 * a2 / m + (b1 + a3) * h1,
        C3: (b1 + a3) * h2 - a2 / m,
        C4: -(b1 + a3),
        C5: -b1 * a3 / m,
    }
}

/// Cn = h'' (Eq. 31) at the CCF state x = [x1, x2, x3, x4].
pub fn ccf_cn<S: Specimen + ?Sized>(specimen: &S, x: &[f64; 4]) -> f64 {
    let [x1, x2, x3, x4] = *x;
    let [h11, h22, h12] = specimen.hess_h(x1, x2);
    let [h1, h2] = specimen.grad_h(x1, x2);
    h11 * x2 * x2 + h22 * x3 * x3 + 2.0 * h12 * x2 * x3 + h1 * x3 + h2 * x4
}

/// Whether the CCF keeps Cn or follows the paper in dropping it for a linear
/// specimen (Sec. 3.2.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CnTerm {
    /// Cn = h'' kept: the CCF is the plant of Eq. 10, exactly.
    Kept,
    /// Cn dropped, as the paper does for a linear specimen: a different model.
    Dropped,
}

/// Time derivative of the CCF state (Eq. 34) with the actuator force
/// recovered from the states, f = m (x3 - h(x1, x2)) (Eq. 9), so the form is
/// closed in [x1..x4] and driven by u alone.
pub fn ccf_derivative<S: Specimen + ?Sized>(
    rig: &RigParams,
    specimen: &S,
    cn: CnTerm,
    x: &[f64; 4],
    u: f64,
) -> [f64; 4] {
    let [x1, x2, x3, x4] = *x;
    let c = ccf_coefficients(rig, specimen, x1, x2);
    let f = specimen.mass_kg() * (x3 - specimen.h(x1, x2));
    let cn_value = match cn {
        CnTerm::Kept => ccf_cn(specimen, x),
        CnTerm::Dropped => 0.0,
    };
    let x4_dot = c.C1 * u - c.C1 * x1 + c.C2 * x2 + c.C3 * x3 + c.C4 * x4 + c.C5 * f + cn_value;
    [x2, x3, x4, x4_dot]
}

/// The CCF of a linear SDOF specimen as a state space in [x1, x2, x3, x4] with
/// outputs [x1, f], f = m x3 + k x1 + c x2 substituted.
///
/// With `CnTerm::Kept` its transfer function is Eq. 17's exactly; with
/// `CnTerm::Dropped` it is the paper's simplified model, whose poles differ.
pub fn ccf_linear_state_space(rig: &RigParams, sdof: &LinearSdof, cn: CnTerm) -> StateSpace {
    let (m, c, k) = (sdof.mass_kg, sdof.damping_ns_per_m, sdof.stiffness_n_per_m);
    let co = ccf_coefficients(rig, sdof, 0.0, 0.0);
    let [h1, h2] = sdof.grad_h(0.0, 0.0);
    let (cn_x3, cn_x4) = match cn {
        CnTerm::Kept => (h1, h2),
        CnTerm::Dropped => (0.0, 0.0),
    };
    #[rustfmt::skip]
    let a = DMatrix::from_row_slice(4, 4, &[
        0.0, 1.0, 0.0, 0.0,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
        -co.C1 + co.C5 * k, co.C2 + co.C5 * c, co.C3 + co.C5 * m + cn_x3, co.C4 + cn_x4,
    ]);
    let b = DVector::from_vec(vec![0.0, 0.0, 0.0, co.C1]);
    #[rustfmt::skip]
    let cm = DMatrix::from_row_slice(2, 4, &[
        1.0, 0.0, 0.0, 0.0,
        k,   c,   m,   0.0,
    ]);
    StateSpace {
        a,
        b,
        c: cm,
        d: DVector::zeros(2),
    }
}

/// Poles of a linear plant, from the state space (not the polynomials);
/// None as [`crate::poly::eigenvalues`] says.
pub fn poles(rig: &RigParams, specimen: &LinearSpecimen) -> Option<Vec<Complex<f64>>> {
    state_space(rig, specimen).eigenvalues()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poly;
    use approx::assert_relative_eq;

    fn exp1() -> LinearSdof {
        LinearSdof {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
        }
    }

    fn specimens() -> Vec<LinearSpecimen> {
        let e = exp1();
        vec![
            LinearSpecimen::None,
            LinearSpecimen::Spring {
                stiffness_n_per_m: 116_640.0,
            },
            LinearSpecimen::Sdof {
                mass_kg: e.mass_kg,
                damping_ns_per_m: e.damping_ns_per_m,
                stiffness_n_per_m: e.stiffness_n_per_m,
            },
            LinearSpecimen::Sdof {
                mass_kg: 3.8,
                damping_ns_per_m: 5.0,
                stiffness_n_per_m: 84_340.0,
            },
        ]
    }

    fn assert_same_roots(a: &[Complex<f64>], b: &[Complex<f64>], rel: f64) {
        assert_eq!(a.len(), b.len(), "{a:?} vs {b:?}");
        for (x, y) in a.iter().zip(b.iter()) {
            assert!(
                (x - y).norm() <= rel * y.norm().max(1.0),
                "root {x} vs {y} (all: {a:?} vs {b:?})"
            );
        }
    }

    #[test]
    fn state_space_eigenvalues_are_the_transfer_function_poles() {
        // Eigenvalues of Eq. 10's A matrix against the roots of Eqs. 12/14/17.
        let rig = PAPER_RIG;
        for spec in specimens() {
            let eig = state_space(&rig, &spec).eigenvalues().unwrap();
            let tf_poles = tf_x1_u(&rig, &spec).unwrap().poles();
            assert_same_roots(&eig, &tf_poles, 1e-9);
        }
    }

    #[test]
    fn closed_form_transfer_functions_match_the_state_space_response() {
        // Eqs. 12, 14, 17 and 45 against (sI - A)^-1 B solved numerically.
        let rig = PAPER_RIG;
        for spec in specimens() {
            let ss = state_space(&rig, &spec);
            let x = tf_x1_u(&rig, &spec).unwrap();
            let f = tf_f_u(&rig, &spec).unwrap();
            for hz in [0.1, 1.0, 5.0, 23.7, 29.4, 60.0] {
                let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * hz);
                let want_x = ss.eval(OUT_X1, s);
                assert!((x.eval(s) - want_x).norm() <= 1e-10 * want_x.norm());
                let want_f = ss.eval(OUT_FORCE, s);
                assert!(
                    (f.eval(s) - want_f).norm() <= 1e-10 * want_f.norm().max(1e-300),
                    "{spec:?} at {hz} Hz"
                );
            }
        }
    }

    #[test]
    fn static_gain_is_one_without_specimen_and_below_one_with_a_spring() {
        let rig = PAPER_RIG;
        assert_relative_eq!(
            tf_x1_u(&rig, &LinearSpecimen::None).unwrap().dc_gain(),
            1.0,
            max_relative = 1e-14
        );
        let k = 116_640.0;
        let g = tf_x1_u(
            &rig,
            &LinearSpecimen::Spring {
                stiffness_n_per_m: k,
            },
        )
        .unwrap()
        .dc_gain();
        // a1b0 / (beta1 a3 k + a1b0), from Eq. 14.
        let want = rig.a1b0_n_per_m_s2 / (rig.beta1_per_s * rig.a3_per_s * k + rig.a1b0_n_per_m_s2);
        assert_relative_eq!(g, want, max_relative = 1e-14);
        assert!(g < 1.0);
    }

    #[test]
    fn specimen_poles_are_zeros_of_the_force_path() {
        // Eq. 45: the zeros of f/u are the roots of m s^2 + c s + k.
        let rig = PAPER_RIG;
        let e = exp1();
        let spec = LinearSpecimen::Sdof {
            mass_kg: e.mass_kg,
            damping_ns_per_m: e.damping_ns_per_m,
            stiffness_n_per_m: e.stiffness_n_per_m,
        };
        let zeros = tf_f_u(&rig, &spec).unwrap().zeros();
        let want = poly::roots(&[e.mass_kg, e.damping_ns_per_m, e.stiffness_n_per_m]);
        assert_same_roots(&zeros, &want, 1e-10);
        assert_relative_eq!(
            spec.natural_frequency_hz().unwrap(),
            29.4,
            max_relative = 2e-3
        );
    }

    #[test]
    fn ccf_with_cn_reproduces_the_fourth_order_transfer_function() {
        // The CCF (Eq. 34) with Cn kept and f substituted must be Eq. 17 exactly.
        let rig = PAPER_RIG;
        for k in [129_400.0, 84_340.0] {
            let sdof = LinearSdof {
                stiffness_n_per_m: k,
                ..exp1()
            };
            let spec = LinearSpecimen::Sdof {
                mass_kg: sdof.mass_kg,
                damping_ns_per_m: sdof.damping_ns_per_m,
                stiffness_n_per_m: k,
            };
            let ccf = ccf_linear_state_space(&rig, &sdof, CnTerm::Kept);
            let want = tf_x1_u(&rig, &spec).unwrap();
            let got = ccf.transfer_function(OUT_X1);
            assert_eq!(got.den.len(), 5);
            for (g, w) in got.den.iter().zip(want.den.iter()) {
                assert_relative_eq!(g, w, max_relative = 1e-11);
            }
            assert_eq!(got.num.len(), 1);
            assert_relative_eq!(got.num[0], want.num[0], max_relative = 1e-11);
            // Force output: Eq. 45.
            let gf = ccf.transfer_function(OUT_FORCE);
            let wf = tf_f_u(&rig, &spec).unwrap();
            for (g, w) in gf.num.iter().zip(wf.num.iter()) {
                assert_relative_eq!(g, w, max_relative = 1e-9);
            }
            assert_same_roots(&ccf.eigenvalues().unwrap(), &want.poles(), 1e-9);
        }
    }

    #[test]
    fn dropping_cn_moves_the_poles() {
        // The paper's simplification is a different model: its characteristic
        // polynomial lacks the k/m s^2 and c/m s^3 terms of Cn.
        let rig = PAPER_RIG;
        let sdof = exp1();
        let kept = ccf_linear_state_space(&rig, &sdof, CnTerm::Kept)
            .eigenvalues()
            .unwrap();
        let dropped = ccf_linear_state_space(&rig, &sdof, CnTerm::Dropped);
        let den_dropped = dropped.transfer_function(OUT_X1).den;
        let den_kept = ccf_linear_state_space(&rig, &sdof, CnTerm::Kept)
            .transfer_function(OUT_X1)
            .den;
        let (m, c, k) = (sdof.mass_kg, sdof.damping_ns_per_m, sdof.stiffness_n_per_m);
        assert_relative_eq!(den_kept[1] - den_dropped[1], c / m, max_relative = 1e-9);
        assert_relative_eq!(den_kept[2] - den_dropped[2], k / m, max_relative = 1e-9);
        let moved = kept
            .iter()
            .zip(dropped.eigenvalues().unwrap().iter())
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(moved > 1.0, "largest pole shift {moved} rad/s");
    }

    #[test]
    fn ccf_derivative_matches_the_physical_plant() {
        // Map a physical state [x1, x2, f, r] to CCF coordinates, x3 = h + f/m
        // and x4 = h' + f'/m (Eqs. 27-28), and compare x4' from Eq. 34 with the
        // derivative of x4 computed from Eq. 10.
        let rig = PAPER_RIG;
        let sdof = exp1();
        let ss = state_space(
            &rig,
            &LinearSpecimen::Sdof {
                mass_kg: sdof.mass_kg,
                damping_ns_per_m: sdof.damping_ns_per_m,
                stiffness_n_per_m: sdof.stiffness_n_per_m,
            },
        );
        let xp = DVector::from_vec(vec![1e-3, -2e-2, 35.0, 4.0e3]);
        let u = 2e-3;
        // x, x', x'', x''', x'''' of the physical plant by repeated application of A.
        let d1 = &ss.a * &xp + &ss.b * u;
        let d2 = &ss.a * &d1; // u constant
        let d3 = &ss.a * &d2;
        let x = [xp[0], xp[1], d1[1], d2[1]];
        let got = ccf_derivative(&rig, &sdof, CnTerm::Kept, &x, u);
        assert_relative_eq!(got[3], d3[1], max_relative = 1e-10);
        assert_relative_eq!(got[2], d2[1], max_relative = 1e-12);
    }

    #[test]
    fn p_gain_scales_a1b0_only() {
        let rig = PAPER_RIG.at_p_gain(2.0);
        assert_relative_eq!(rig.a1b0_n_per_m_s2, 4.824e9, max_relative = 1e-12);
        // Exact: a2 does not depend on the P gain and is copied.
        assert_eq!(rig.a2_n_per_m, 7.881e5);
        assert_relative_eq!(rig.r1(), 2.0 * 2.412e9 / 7.881e5, max_relative = 1e-12);
    }
}

#[cfg(test)]
mod band_tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// The first-order stds of a validation run's predicted x1/u against
    /// 20,000 rigs drawn from a correlated covariance (0.3-0.5 % stds):
    /// the sample std of each draw's magnitude and phase agrees within 5 %
    /// at every frequency, through the specimen's resonance.
    #[test]
    fn x1_u_std_matches_draws_from_the_rig_covariance() {
        let rig = PAPER_RIG;
        let spec = LinearSpecimen::Sdof {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
        };
        let th = [
            rig.beta1_per_s,
            rig.a1b0_n_per_m_s2,
            rig.a2_n_per_m,
            rig.a3_per_s,
        ];
        let sd = [0.003 * th[0], 0.004 * th[1], 0.005 * th[2], 0.004 * th[3]];
        let corr = [
            [1.0, 0.2, 0.1, 0.5],
            [0.2, 1.0, 0.9, 0.0],
            [0.1, 0.9, 1.0, 0.1],
            [0.5, 0.0, 0.1, 1.0],
        ];
        let cov: [[f64; 4]; 4] =
            std::array::from_fn(|i| std::array::from_fn(|j| corr[i][j] * sd[i] * sd[j]));
        let freqs = [1.0, 10.0, 25.0, 29.4, 40.0];
        let (mag, phase) = x1_u_std(&rig, &cov, &spec, &freqs).unwrap();
        let l = DMatrix::from_fn(4, 4, |i, j| cov[i][j])
            .cholesky()
            .unwrap()
            .l();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = 20_000;
        let mut acc = vec![[0.0f64; 4]; freqs.len()];
        for _ in 0..n {
            let z = DVector::from_iterator(4, (0..4).map(|_| StandardNormal.sample(&mut rng)));
            let d = &l * z;
            let r = RigParams {
                beta1_per_s: th[0] + d[0],
                a1b0_n_per_m_s2: th[1] + d[1],
                a2_n_per_m: th[2] + d[2],
                a3_per_s: th[3] + d[3],
                p_gain: rig.p_gain,
            };
            let (tf, tf0) = (tf_x1_u(&r, &spec).unwrap(), tf_x1_u(&rig, &spec).unwrap());
            for (k, &f) in freqs.iter().enumerate() {
                let (g, g0) = (tf.freq_response(f), tf0.freq_response(f));
                let (m, p) = (20.0 * g.norm().log10(), (g / g0).arg());
                let a = &mut acc[k];
                *a = [a[0] + m, a[1] + m * m, a[2] + p, a[3] + p * p];
            }
        }
        let nf = n as f64;
        for (k, a) in acc.iter().enumerate() {
            let sd = |s: f64, s2: f64| ((s2 - s * s / nf) / (nf - 1.0)).sqrt();
            let (m, p) = (sd(a[0], a[1]), sd(a[2], a[3]));
            assert!(
                (m / mag[k] - 1.0).abs() < 0.05,
                "{} Hz: {m} vs {}",
                freqs[k],
                mag[k]
            );
            assert!(
                (p / phase[k] - 1.0).abs() < 0.05,
                "{} Hz: {p} vs {}",
                freqs[k],
                phase[k]
            );
        }
    }
}
