//! Numerical integration of nonlinear plants driven through a sample-and-hold:
//! the command is constant over each sample period, so every step ends on a
//! sample instant (where the input jumps) and the integrators never straddle
//! one. Classical RK4 with a fixed number of substeps, and Dormand-Prince
//! 5(4) with the standard error control of Hairer, Norsett & Wanner, Solving
//! Ordinary Differential Equations I (2nd ed.), Sec. II.4 (step-size
//! selection, starting step) and II.5 (the DOPRI5 tableau).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A system x' = F(x, u) with a scalar input.
pub trait OdeSystem {
    /// Number of states.
    fn dim(&self) -> usize;
    /// Writes F(x, u) into `dx` (both of length `dim()`).
    fn deriv(&self, x: &[f64], u: f64, dx: &mut [f64]);
}

/// How to integrate over each sample period.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "method", rename_all = "snake_case", deny_unknown_fields)]
pub enum Integrator {
    /// Classical fourth-order Runge-Kutta, `substeps` equal steps per sample.
    Rk4 { substeps: usize },
    /// Dormand-Prince 5(4) with local error below atol + rtol |x| per state
    /// (weighted rms norm, Hairer et al. II.4 Eq. 4.11).
    DormandPrince { rtol: f64, atol: f64 },
}

impl Default for Integrator {
    fn default() -> Self {
        Integrator::DormandPrince {
            rtol: 1e-9,
            atol: 1e-12,
        }
    }
}

/// Why an integration failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OdeError {
    #[error("integrator setting {name} must be {requirement} (got {value})")]
    Setting {
        name: &'static str,
        value: f64,
        requirement: &'static str,
    },
    #[error("the initial state has {got} component(s) but the system has {dim} state(s)")]
    Dimension { got: usize, dim: usize },
    #[error("command sample {index} is not finite ({value})")]
    NonFiniteInput { index: usize, value: f64 },
    #[error(
        "the state became non-finite at t = {t_s} s (state {component}): the system diverged or the step size is beyond the integrator's stability limit"
    )]
    NonFinite { t_s: f64, component: usize },
    #[error(
        "step size underflow at t = {t_s} s (h = {h_s} s): the problem is too stiff or singular there"
    )]
    StepSizeUnderflow { t_s: f64, h_s: f64 },
    #[error(
        "more than {max_steps} steps in the sample period starting at t = {t_s} s: the problem is too stiff for an explicit integrator"
    )]
    TooManySteps { t_s: f64, max_steps: usize },
}

/// What [`integrate_held`] reports to its observer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// The state at sample instant t_k.
    Sample(usize),
    /// The state at `t_k + taps_s[tap]` inside sample period k.
    Tap { interval: usize, tap: usize },
}

/// Steps allowed per sample period before [`OdeError::TooManySteps`].
const MAX_STEPS_PER_SAMPLE: usize = 100_000;

/// Integrates from `x0` at t = 0 with `u[k]` held over `[t_k, t_k + dt_s)`, and
/// returns the states at every sample instant: `out[j][k]` is state j at
/// t_k = k dt_s (`out[j][0] = x0[j]`; one vector per state, each as long
/// as `u`).
pub fn simulate_held<S: OdeSystem>(
    sys: &S,
    u: &[f64],
    dt_s: f64,
    x0: &[f64],
    integ: Integrator,
) -> Result<Vec<Vec<f64>>, OdeError> {
    let mut out = vec![vec![0.0; u.len()]; sys.dim()];
    integrate_held(sys, u, dt_s, x0, integ, &[], |event, x| {
        if let Event::Sample(k) = event {
            for (col, v) in out.iter_mut().zip(x) {
                col[k] = *v;
            }
        }
    })?;
    Ok(out)
}

/// As [`simulate_held`], but hands each state to `observe` instead of storing
/// it, and also stops at t_k + `taps_s[i]` inside every period (each tap in
/// (0, dt_s); the input does not change there, the steps just end on it).
/// Sample k is observed for k in 0..u.len(); taps in periods 0..u.len()-1.
pub fn integrate_held<S: OdeSystem, F: FnMut(Event, &[f64])>(
    sys: &S,
    u: &[f64],
    dt_s: f64,
    x0: &[f64],
    integ: Integrator,
    taps_s: &[f64],
    mut observe: F,
) -> Result<(), OdeError> {
    let dim = sys.dim();
    if x0.len() != dim {
        return Err(OdeError::Dimension { got: x0.len(), dim });
    }
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(OdeError::Setting {
            name: "dt_s",
            value: dt_s,
            requirement: "positive and finite",
        });
    }
    for &tap in taps_s {
        if !(tap > 0.0 && tap < dt_s) {
            return Err(OdeError::Setting {
                name: "taps_s",
                value: tap,
                requirement: "inside the sample period (0, dt_s)",
            });
        }
    }
    if let Some((index, &value)) = u.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(OdeError::NonFiniteInput { index, value });
    }
    if let Some(component) = x0.iter().position(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite {
            t_s: 0.0,
            component,
        });
    }
    // Segment ends inside a period: the taps in increasing order, then dt_s.
    let mut order: Vec<usize> = (0..taps_s.len()).collect();
    order.sort_by(|&a, &b| taps_s[a].total_cmp(&taps_s[b]));
    let mut stepper = Stepper::new(sys, integ, dt_s)?;
    let mut x = x0.to_vec();
    for k in 0..u.len() {
        observe(Event::Sample(k), &x);
        if k + 1 == u.len() {
            break;
        }
        let t_k = k as f64 * dt_s;
        let mut from = 0.0;
        stepper.new_input();
        for &tap in &order {
            let to = taps_s[tap];
            if to > from {
                stepper.advance(sys, &mut x, u[k], t_k, from, to)?;
                from = to;
            }
            observe(Event::Tap { interval: k, tap }, &x);
        }
        stepper.advance(sys, &mut x, u[k], t_k, from, dt_s)?;
    }
    Ok(())
}

/// Scratch space and step-size memory of one integration; no allocation
/// after construction.
struct Stepper {
    integ: Integrator,
    dt_s: f64,
    k: [Vec<f64>; 7],
    tmp: Vec<f64>,
    y_new: Vec<f64>,
    /// Dormand-Prince: the proposed next step (None before the first step).
    h: Option<f64>,
    /// Dormand-Prince: k[0] holds F(x, u) for the current x and input.
    k1_valid: bool,
}

// The stage loops index several state-sized buffers at once; ranges read
// closer to the tableau than zipped iterators.
#[allow(clippy::needless_range_loop)]
// Dormand & Prince (1980), Hairer et al. II.5 Table 5.2.
// The system is autonomous over a segment (u held), so the nodes c_i
// are not needed.
const A2: [f64; 1] = [1.0 / 5.0];
const A3: [f64; 2] = [3.0 / 40.0, 9.0 / 40.0];
const A4: [f64; 3] = [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0];
const A5: [f64; 4] = [
    19372.0 / 6561.0,
    -25360.0 / 2187.0,
    64448.0 / 6561.0,
    -212.0 / 729.0,
];
const A6: [f64; 5] = [
    9017.0 / 3168.0,
    -355.0 / 33.0,
    46732.0 / 5247.0,
    49.0 / 176.0,
    -5103.0 / 18656.0,
];
// Fifth-order weights (= the last stage's row: FSAL).
const B: [f64; 6] = [
    35.0 / 384.0,
    0.0,
    500.0 / 1113.0,
    125.0 / 192.0,
    -2187.0 / 6784.0,
    11.0 / 84.0,
];
// B minus the embedded fourth-order weights.
const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

impl Stepper {
    fn new<S: OdeSystem>(sys: &S, integ: Integrator, dt_s: f64) -> Result<Self, OdeError> {
        match integ {
            Integrator::Rk4 { substeps } => {
                if substeps == 0 {
                    return Err(OdeError::Setting {
                        name: "substeps",
                        value: 0.0,
                        requirement: "at least 1",
                    });
                }
            }
            Integrator::DormandPrince { rtol, atol } => {
                for (name, value) in [("rtol", rtol), ("atol", atol)] {
                    if !(value.is_finite() && value > 0.0) {
                        return Err(OdeError::Setting {
                            name,
                            value,
                            requirement: "positive and finite",
                        });
                    }
                }
            }
        }
        let n = sys.dim();
        Ok(Self {
            integ,
            dt_s,
            k: std::array::from_fn(|_| vec![0.0; n]),
            tmp: vec![0.0; n],
            y_new: vec![0.0; n],
            h: None,
            k1_valid: false,
        })
    }

    /// The input changes at a sample instant: derivatives must be recomputed.
    fn new_input(&mut self) {
        self.k1_valid = false;
    }

    /// Integrates x from t_k + from to t_k + to with the input held at u.
    fn advance<S: OdeSystem>(
        &mut self,
        sys: &S,
        x: &mut [f64],
        u: f64,
        t_k: f64,
        from: f64,
        to: f64,
    ) -> Result<(), OdeError> {
        match self.integ {
            Integrator::Rk4 { substeps } => {
                // Steps of at most dt / substeps; a full period takes exactly
                // `substeps` equal steps.
                let len = to - from;
                let steps = ((substeps as f64 * len / self.dt_s) * (1.0 - 1e-12))
                    .ceil()
                    .max(1.0) as usize;
                let h = len / steps as f64;
                for s in 0..steps {
                    self.rk4_step(sys, x, u, h);
                    if let Some(component) = x.iter().position(|v| !v.is_finite()) {
                        return Err(OdeError::NonFinite {
                            t_s: t_k + from + (s + 1) as f64 * h,
                            component,
                        });
                    }
                }
                Ok(())
            }
            Integrator::DormandPrince { rtol, atol } => {
                self.dopri_segment(sys, x, u, t_k, from, to, rtol, atol)
            }
        }
    }

    fn rk4_step<S: OdeSystem>(&mut self, sys: &S, x: &mut [f64], u: f64, h: f64) {
        let n = x.len();
        let [k1, k2, k3, k4, ..] = &mut self.k;
        let tmp = &mut self.tmp;
        sys.deriv(x, u, k1);
        for i in 0..n {
            tmp[i] = x[i] + 0.5 * h * k1[i];
        }
        sys.deriv(tmp, u, k2);
        for i in 0..n {
            tmp[i] = x[i] + 0.5 * h * k2[i];
        }
        sys.deriv(tmp, u, k3);
        for i in 0..n {
            tmp[i] = x[i] + h * k3[i];
        }
        sys.deriv(tmp, u, k4);
        for i in 0..n {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }

    /// Hairer et al. II.4: a starting step from the size of x, F(x) and an
    /// Euler step's change of F.
    fn initial_step<S: OdeSystem>(
        &mut self,
        sys: &S,
        x: &[f64],
        u: f64,
        rtol: f64,
        atol: f64,
    ) -> f64 {
        let n = x.len() as f64;
        let f0 = &self.k[0];
        let (mut d0, mut d1) = (0.0, 0.0);
        for i in 0..x.len() {
            let sc = atol + rtol * x[i].abs();
            d0 += (x[i] / sc).powi(2);
            d1 += (f0[i] / sc).powi(2);
        }
        let (d0, d1) = ((d0 / n).sqrt(), (d1 / n).sqrt());
        let h0 = if d0 < 1e-5 || d1 < 1e-5 {
            1e-6
        } else {
            0.01 * d0 / d1
        };
        for i in 0..x.len() {
            self.tmp[i] = x[i] + h0 * f0[i];
        }
        let (kk, rest) = self.k.split_at_mut(1);
        sys.deriv(&self.tmp, u, &mut rest[0]);
        let mut d2 = 0.0;
        for i in 0..x.len() {
            let sc = atol + rtol * x[i].abs();
            d2 += ((rest[0][i] - kk[0][i]) / sc).powi(2);
        }
        let d2 = (d2 / n).sqrt() / h0;
        let h1 = if d1.max(d2) <= 1e-15 {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / d1.max(d2)).powf(1.0 / 5.0)
        };
        (100.0 * h0).min(h1)
    }

    /// One Dormand-Prince trial step of size `h` from `x` (k1 in `self.k[0]`):
    /// the stages into `self.k`, the fifth-order solution into `self.y_new`
    /// with its derivative (FSAL) into `self.k[6]`, and the RMS of the
    /// embedded error estimate scaled by the tolerances.
    fn trial_step<S: OdeSystem>(
        &mut self,
        sys: &S,
        x: &[f64],
        u: f64,
        h: f64,
        rtol: f64,
        atol: f64,
    ) -> f64 {
        let stages: [&[f64]; 5] = [&A2, &A3, &A4, &A5, &A6];
        for (s, a) in stages.iter().enumerate() {
            for (i, xi) in x.iter().enumerate() {
                let mut acc = 0.0;
                for (j, aj) in a.iter().enumerate() {
                    acc += aj * self.k[j][i];
                }
                self.tmp[i] = xi + h * acc;
            }
            let (_, rest) = self.k.split_at_mut(s + 1);
            sys.deriv(&self.tmp, u, &mut rest[0]);
        }
        for (i, xi) in x.iter().enumerate() {
            let mut acc = 0.0;
            for (j, bj) in B.iter().enumerate() {
                acc += bj * self.k[j][i];
            }
            self.y_new[i] = xi + h * acc;
        }
        {
            let (_, rest) = self.k.split_at_mut(6);
            sys.deriv(&self.y_new, u, &mut rest[0]);
        }
        let mut err = 0.0;
        for (i, xi) in x.iter().enumerate() {
            let mut acc = 0.0;
            for (j, ej) in E.iter().enumerate() {
                acc += ej * self.k[j][i];
            }
            let sc = atol + rtol * xi.abs().max(self.y_new[i].abs());
            err += (h * acc / sc).powi(2);
        }
        (err / x.len() as f64).sqrt()
    }

    #[allow(clippy::too_many_arguments)]
    fn dopri_segment<S: OdeSystem>(
        &mut self,
        sys: &S,
        x: &mut [f64],
        u: f64,
        t_k: f64,
        from: f64,
        to: f64,
        rtol: f64,
        atol: f64,
    ) -> Result<(), OdeError> {
        const SAFETY: f64 = 0.9;
        const FAC_MIN: f64 = 0.2;
        const FAC_MAX: f64 = 5.0;

        if !self.k1_valid {
            sys.deriv(x, u, &mut self.k[0]);
            self.k1_valid = true;
        }
        let mut h_prop = match self.h {
            Some(h) => h,
            None => self.initial_step(sys, x, u, rtol, atol),
        };
        let mut t = from;
        let mut steps = 0;
        let mut rejected_last = false;
        let mut nonfinite: Option<usize> = None;
        while t < to {
            steps += 1;
            if steps > MAX_STEPS_PER_SAMPLE {
                return Err(OdeError::TooManySteps {
                    t_s: t_k,
                    max_steps: MAX_STEPS_PER_SAMPLE,
                });
            }
            let remaining = to - t;
            // Land exactly on the segment end; avoid a sliver step after it.
            let (h, clipped) = if h_prop >= remaining * (1.0 - 1e-10) {
                (remaining, true)
            } else {
                (h_prop, false)
            };
            if h <= 10.0 * f64::EPSILON * (t_k + t).abs().max(self.dt_s) && !clipped {
                return Err(match nonfinite {
                    Some(component) => OdeError::NonFinite {
                        t_s: t_k + t,
                        component,
                    },
                    None => OdeError::StepSizeUnderflow {
                        t_s: t_k + t,
                        h_s: h,
                    },
                });
            }
            let err = self.trial_step(sys, x, u, h, rtol, atol);
            if let Some(component) = self.y_new.iter().position(|v| !v.is_finite()) {
                nonfinite = Some(component);
                h_prop = h * FAC_MIN;
                rejected_last = true;
                continue;
            }
            if !err.is_finite() || err > 1.0 {
                let fac = if err.is_finite() {
                    (SAFETY * err.powf(-0.2)).max(FAC_MIN)
                } else {
                    FAC_MIN
                };
                h_prop = h * fac.min(1.0);
                rejected_last = true;
                continue;
            }
            // Accepted.
            x.copy_from_slice(&self.y_new);
            self.k.swap(0, 6);
            t = if clipped { to } else { t + h };
            let fac_max = if rejected_last { 1.0 } else { FAC_MAX };
            let fac = if err == 0.0 {
                fac_max
            } else {
                (SAFETY * err.powf(-0.2)).clamp(FAC_MIN, fac_max)
            };
            // A step cut short to land on the segment end says nothing new
            // about the step size unless the error asks for a smaller one.
            h_prop = match (clipped, fac < 1.0) {
                (true, true) => h_prop.min(h * fac),
                (true, false) => h_prop,
                (false, _) => h * fac,
            };
            rejected_last = false;
            nonfinite = None;
        }
        self.h = Some(h_prop);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// x' = -a x + b u.
    struct Lag {
        a: f64,
        b: f64,
    }

    impl OdeSystem for Lag {
        fn dim(&self) -> usize {
            1
        }
        fn deriv(&self, x: &[f64], u: f64, dx: &mut [f64]) {
            dx[0] = -self.a * x[0] + self.b * u;
        }
    }

    /// Undamped oscillator, x'' = -w^2 x: energy must be kept.
    struct Oscillator {
        w: f64,
    }

    impl OdeSystem for Oscillator {
        fn dim(&self) -> usize {
            2
        }
        fn deriv(&self, x: &[f64], _u: f64, dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -self.w * self.w * x[0];
        }
    }

    #[test]
    fn held_input_gives_the_exact_piecewise_exponential() {
        // With u held, x(t_{k+1}) = e^{-aT} x_k + (1 - e^{-aT}) b/a u_k.
        let sys = Lag { a: 20.0, b: 3.0 };
        let dt = 0.01;
        let u: Vec<f64> = (0..200).map(|k| ((k as f64) * 0.37).sin()).collect();
        let mut want = vec![0.5];
        let e = (-sys.a * dt).exp();
        for k in 0..u.len() - 1 {
            let next = e * want[k] + (1.0 - e) * sys.b / sys.a * u[k];
            want.push(next);
        }
        for integ in [
            Integrator::Rk4 { substeps: 20 },
            Integrator::DormandPrince {
                rtol: 1e-11,
                atol: 1e-13,
            },
        ] {
            let x = simulate_held(&sys, &u, dt, &[0.5], integ).unwrap();
            assert_eq!(x[0].len(), u.len());
            for k in 0..u.len() {
                // RK4 local error ~ (a h)^5 / 120 = 1e-9 per step, 20 per sample.
                assert!(
                    (x[0][k] - want[k]).abs() < 2e-9,
                    "{integ:?} k = {k}: {} vs {}",
                    x[0][k],
                    want[k]
                );
            }
        }
    }

    #[test]
    fn dormand_prince_meets_its_tolerance_on_an_oscillator() {
        // x = cos(w t): over 10 periods the global error stays near the
        // requested tolerance (Hairer et al. II.4: error proportional to tol).
        let sys = Oscillator {
            w: 2.0 * std::f64::consts::PI,
        };
        let u = vec![0.0; 1001];
        let dt = 0.01;
        let x = simulate_held(
            &sys,
            &u,
            dt,
            &[1.0, 0.0],
            Integrator::DormandPrince {
                rtol: 1e-10,
                atol: 1e-12,
            },
        )
        .unwrap();
        for k in (0..u.len()).step_by(50) {
            let t = k as f64 * dt;
            assert!((x[0][k] - (sys.w * t).cos()).abs() < 1e-8, "t = {t}");
        }
    }

    #[test]
    fn taps_report_the_state_inside_the_period() {
        // x' = u with u held: at t_k + tap, x = x_k + u_k tap exactly.
        let sys = Lag { a: 0.0, b: 1.0 };
        let u = [1.0, -2.0, 4.0, 0.5];
        let dt = 0.1;
        let taps = [0.07, 0.03];
        let mut seen = Vec::new();
        integrate_held(
            &sys,
            &u,
            dt,
            &[0.0],
            Integrator::Rk4 { substeps: 3 },
            &taps,
            |e, x| seen.push((e, x[0])),
        )
        .unwrap();
        let mut x = 0.0;
        let mut want = Vec::new();
        for k in 0..u.len() {
            want.push((Event::Sample(k), x));
            if k + 1 < u.len() {
                want.push((
                    Event::Tap {
                        interval: k,
                        tap: 1,
                    },
                    x + u[k] * 0.03,
                ));
                want.push((
                    Event::Tap {
                        interval: k,
                        tap: 0,
                    },
                    x + u[k] * 0.07,
                ));
                x += u[k] * dt;
            }
        }
        assert_eq!(seen.len(), want.len());
        for ((e1, v1), (e2, v2)) in seen.iter().zip(want.iter()) {
            assert_eq!(e1, e2);
            assert_relative_eq!(*v1, *v2, epsilon = 1e-15);
        }
    }

    /// x' = x^2: blows up at t = 1 / x0.
    struct Blowup;

    impl OdeSystem for Blowup {
        fn dim(&self) -> usize {
            1
        }
        fn deriv(&self, x: &[f64], _u: f64, dx: &mut [f64]) {
            dx[0] = x[0] * x[0];
        }
    }

    #[test]
    fn divergence_and_bad_settings_are_reported_with_where() {
        let u = vec![0.0; 300];
        // Finite-time blow-up at t = 1 s: DP's steps shrink until they underflow.
        let e = simulate_held(
            &Blowup,
            &u,
            0.01,
            &[1.0],
            Integrator::DormandPrince {
                rtol: 1e-8,
                atol: 1e-10,
            },
        )
        .unwrap_err();
        match e {
            OdeError::StepSizeUnderflow { t_s, .. } | OdeError::NonFinite { t_s, .. } => {
                assert!((t_s - 1.0).abs() < 0.01, "{e}")
            }
            other => panic!("unexpected {other}"),
        }
        // RK4 with a coarse step overflows to infinity after the singularity.
        let e =
            simulate_held(&Blowup, &u, 0.01, &[1.0], Integrator::Rk4 { substeps: 1 }).unwrap_err();
        let OdeError::NonFinite { t_s, component } = e else {
            panic!("unexpected {e}")
        };
        assert_eq!(component, 0);
        assert!((0.99..1.2).contains(&t_s), "{t_s}");
        assert!(e.to_string().starts_with(&format!(
            "the state became non-finite at t = {t_s} s (state 0)"
        )));
        // Stiffness beyond RK4's stability: x' = -1e5 x with h = 1e-3.
        let stiff = Lag { a: 1e5, b: 0.0 };
        let e =
            simulate_held(&stiff, &u, 1e-3, &[1.0], Integrator::Rk4 { substeps: 1 }).unwrap_err();
        assert!(matches!(e, OdeError::NonFinite { .. }), "{e}");
        assert_eq!(
            simulate_held(&stiff, &u, 1e-3, &[1.0], Integrator::Rk4 { substeps: 0 })
                .unwrap_err()
                .to_string(),
            "integrator setting substeps must be at least 1 (got 0)"
        );
        assert_eq!(
            simulate_held(
                &stiff,
                &u,
                1e-3,
                &[1.0],
                Integrator::DormandPrince {
                    rtol: 0.0,
                    atol: 1e-9
                }
            )
            .unwrap_err()
            .to_string(),
            "integrator setting rtol must be positive and finite (got 0)"
        );
        assert_eq!(
            simulate_held(&stiff, &u, 1e-3, &[1.0, 2.0], Integrator::default())
                .unwrap_err()
                .to_string(),
            "the initial state has 2 component(s) but the system has 1 state(s)"
        );
        assert_eq!(
            simulate_held(
                &stiff,
                &[0.0, f64::INFINITY],
                1e-3,
                &[1.0],
                Integrator::default()
            )
            .unwrap_err()
            .to_string(),
            "command sample 1 is not finite (inf)"
        );
    }
}
