//! A specimen driven alone by a prescribed force, to check the specimens
//! of [`crate::model::specimen`] against analytic results without the rig.

use super::ode::OdeSystem;
use super::{SimError, require_positive};
use crate::model::SpecimenModel;

/// A specimen alone, driven by a prescribed force (N) as the input:
/// states [x1, x2, z...], m x2' = F - g(x1, x2, z). For checking specimens
/// against analytic results without the rig.
#[derive(Debug, Clone, Copy)]
pub struct ForcedSpecimen<'a> {
    specimen: &'a SpecimenModel,
    mass_kg: f64,
}

impl<'a> ForcedSpecimen<'a> {
    /// Fails for invalid parameters or a massless specimen.
    pub fn new(specimen: &'a SpecimenModel) -> Result<Self, SimError> {
        specimen.validate()?;
        let mass_kg = specimen.mass_kg();
        require_positive(specimen.name(), "mass_kg", mass_kg)?;
        Ok(Self { specimen, mass_kg })
    }
}

impl OdeSystem for ForcedSpecimen<'_> {
    fn dim(&self) -> usize {
        2 + self.specimen.internal_states()
    }
    fn deriv(&self, x: &[f64], u: f64, dx: &mut [f64]) {
        let g = self.specimen.restoring_force_n(x[0], x[1], &x[2..]);
        dx[0] = x[1];
        dx[1] = (u - g) / self.mass_kg;
        self.specimen.internal_rates(x[1], &x[2..], &mut dx[2..]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Specimen;
    use crate::model::specimen::{BoucWen, Duffing, Friction};
    use crate::simulate::ode::{Integrator, simulate_held};
    use approx::assert_relative_eq;
    use std::f64::consts::PI;

    fn duffing() -> Duffing {
        Duffing {
            mass_kg: 1.0,
            damping_ns_per_m: 20.0,
            stiffness_n_per_m: 1.0e4,
            cubic_stiffness_n_per_m3: 7.2e5,
        }
    }

    fn friction() -> Friction {
        Friction {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 1.294e5,
            coulomb_force_n: 40.0,
            smoothing_velocity_m_per_s: 2e-3,
        }
    }

    #[test]
    fn specimen_derivatives_match_finite_differences() {
        // Central differences of h (and of its gradient), step 1e-6 of scale.
        let specs: [Box<dyn Specimen>; 2] = [Box::new(duffing()), Box::new(friction())];
        for s in specs.iter() {
            for &(x1, x2) in &[(0.0, 0.0), (3e-3, -1e-3), (-8e-3, 4e-3), (1e-2, 2.5e-2)] {
                let (e1, e2) = (1e-8, 1e-8);
                let g = s.grad_h(x1, x2);
                let d1 = (s.h(x1 + e1, x2) - s.h(x1 - e1, x2)) / (2.0 * e1);
                let d2 = (s.h(x1, x2 + e2) - s.h(x1, x2 - e2)) / (2.0 * e2);
                assert_relative_eq!(g[0], d1, max_relative = 1e-6, epsilon = 1e-6);
                assert_relative_eq!(g[1], d2, max_relative = 1e-6, epsilon = 1e-6);
                let hs = s.hess_h(x1, x2);
                let d11 = (s.grad_h(x1 + e1, x2)[0] - s.grad_h(x1 - e1, x2)[0]) / (2.0 * e1);
                let d22 = (s.grad_h(x1, x2 + e2)[1] - s.grad_h(x1, x2 - e2)[1]) / (2.0 * e2);
                let d12 = (s.grad_h(x1, x2 + e2)[0] - s.grad_h(x1, x2 - e2)[0]) / (2.0 * e2);
                let scale = hs.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
                assert!((hs[0] - d11).abs() < 1e-5 * scale, "{} vs {d11}", hs[0]);
                assert!((hs[1] - d22).abs() < 1e-5 * scale, "{} vs {d22}", hs[1]);
                assert!((hs[2] - d12).abs() < 1e-5 * scale, "{} vs {d12}", hs[2]);
            }
        }
    }

    /// Amplitude of the fundamental of y over whole periods [a, b) of w.
    fn fundamental_amplitude(y: &[f64], dt: f64, w: f64, a: usize, b: usize) -> f64 {
        let (mut s, mut c) = (0.0, 0.0);
        for (k, v) in y.iter().enumerate().take(b).skip(a) {
            let t = k as f64 * dt;
            s += v * (w * t).sin();
            c += v * (w * t).cos();
        }
        let m = (b - a) as f64 / 2.0;
        (s * s + c * c).sqrt() / m
    }

    #[test]
    fn forced_duffing_matches_harmonic_balance() {
        // First-order harmonic balance for m x'' + c x' + k x + k3 x^3 = F cos
        // wt with x = A cos(wt - phi): [(k - m w^2) A + 3/4 k3 A^3]^2 + (c w
        // A)^2 = F^2 (e.g. Nayfeh & Mook, Nonlinear Oscillations, Sec. 4.1).
        // Below resonance (w = 0.63 wn) with (3/4) k3 A^2 / (k - m w^2) = 2.3 %,
        // the response is single-valued and the neglected third harmonic is
        // about 1/3 of 2.3 % / |1 - 9 w^2 / wn^2| = 0.3 % of A; its effect on
        // the fundamental is second order in it: within 2e-4 (3.7e-5 seen),
        // while the linear answer is 2 % away.
        let d = duffing();
        let (m, c, k, k3) = (
            d.mass_kg,
            d.damping_ns_per_m,
            d.stiffness_n_per_m,
            d.cubic_stiffness_n_per_m3,
        );
        let w: f64 = 2.0 * PI * 10.0; // rad/s; a period is 2000 samples at 20 kHz
        let f_amp = 100.0;
        // Solve the HB cubic for A by bisection (monotonic below resonance).
        let residual = |a: f64| {
            ((k - m * w * w) * a + 0.75 * k3 * a.powi(3)).powi(2) + (c * w * a).powi(2)
                - f_amp * f_amp
        };
        let (mut lo, mut hi) = (0.0, 0.1);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if residual(mid) > 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let a_hb = 0.5 * (lo + hi);
        let linear_a = f_amp / ((k - m * w * w).powi(2) + (c * w).powi(2)).sqrt();
        assert!(
            a_hb < linear_a * 0.99,
            "hardening shrinks the response below resonance"
        );

        // Force held at 20 kHz: the hold's sinc(wT/2) = 1 - 2e-6 and its
        // images are negligible at this rate.
        let fs = 20_000.0;
        let dt = 1.0 / fs;
        let period = 2.0 * PI / w;
        let n = (20.0 * period * fs).round() as usize; // 2 s; the transient decays as e^{-c t / 2m} = e^{-10 t}
        let u: Vec<f64> = (0..n).map(|j| f_amp * (w * j as f64 * dt).cos()).collect();
        let model = SpecimenModel::Duffing(d);
        let sys = ForcedSpecimen::new(&model).unwrap();
        let x = simulate_held(&sys, &u, dt, &[0.0, 0.0], Integrator::Rk4 { substeps: 1 }).unwrap();
        // The last five periods (whole samples); transient left e^{-10 * 1.5} = 3e-7.
        let b = n;
        let a = b - (5.0 * period * fs).round() as usize;
        let got = fundamental_amplitude(&x[0], dt, w, a, b);
        assert_relative_eq!(got, a_hb, max_relative = 2e-4);
        // And it is distinguishable from the linear answer.
        assert!((got - linear_a).abs() > 0.01 * a_hb);
    }

    #[test]
    fn bouc_wen_monotonic_loading_follows_the_closed_form() {
        // n = 1, x2 > 0, z > 0: dz/dx = A - (beta + gamma) z, so
        // z(x) = A / (beta + gamma) (1 - exp(-(beta + gamma) x)).
        let b = BoucWen {
            mass_kg: 1.0,
            damping_ns_per_m: 0.0,
            stiffness_n_per_m: 1e5,
            alpha: 0.1,
            a: 1.0,
            beta_per_m_pow_n: 300.0,
            gamma_per_m_pow_n: 200.0,
            n: 1.0,
        };
        // Prescribed velocity v0 as the input: states [x1, z].
        struct Kinematic(BoucWen);
        impl OdeSystem for Kinematic {
            fn dim(&self) -> usize {
                2
            }
            fn deriv(&self, x: &[f64], u: f64, dx: &mut [f64]) {
                dx[0] = u;
                dx[1] = self.0.z_rate(u, x[1]);
            }
        }
        let v0 = 0.02;
        let u = vec![v0; 1001];
        let dt = 1e-3; // x reaches 0.02 m = 10 / (beta + gamma)
        let x = simulate_held(
            &Kinematic(b),
            &u,
            dt,
            &[0.0, 0.0],
            Integrator::DormandPrince {
                rtol: 1e-12,
                atol: 1e-15,
            },
        )
        .unwrap();
        let s = b.beta_per_m_pow_n + b.gamma_per_m_pow_n;
        for k in (0..u.len()).step_by(25) {
            let xk = v0 * k as f64 * dt;
            assert_relative_eq!(x[0][k], xk, max_relative = 1e-12, epsilon = 1e-18);
            let want = b.a / s * (1.0 - (-s * xk).exp());
            assert!(
                (x[1][k] - want).abs() < 1e-10 * (b.a / s),
                "k = {k}: {} vs {want}",
                x[1][k]
            );
        }
        // Unloading (x2 < 0, z > 0): dz/dx = A - (gamma - beta) z, steeper than
        // loading when beta > gamma, the hysteresis.
        assert!(b.z_rate(-1.0, 1e-3) / -1.0 > b.z_rate(1.0, 1e-3));
    }

    #[test]
    fn bouc_wen_cycle_balances_energy() {
        // Over any interval: work of the applied force = change of kinetic
        // energy + change of elastic energy alpha k x^2 / 2 + change of the
        // hysteretic element's stored energy (1 - alpha) k z^2 / (2A) +
        // viscous dissipation c x2^2 + hysteretic dissipation (1 - alpha) k / A
        // (beta |x2| |z|^(n+1) + gamma x2 z |z|^n), from z x2 = (z z' + z (beta
        // |x2| |z|^(n-1) z + gamma x2 |z|^n)) / A.
        // The force is held per sample, so its work over a period is exactly
        // F_k (x_{k+1} - x_k); the dissipation integrals use Simpson's rule on
        // a 50 kHz grid (the integrand has a kink where x2 changes sign:
        // error O(h^2) there), hence the 1e-6 relative tolerance.
        for n_exp in [1.0, 2.0] {
            let b = BoucWen {
                mass_kg: 2.0,
                damping_ns_per_m: 30.0,
                stiffness_n_per_m: 2e4,
                alpha: 0.2,
                a: 1.0,
                beta_per_m_pow_n: if n_exp == 1.0 { 400.0 } else { 1.6e5 },
                gamma_per_m_pow_n: if n_exp == 1.0 { 100.0 } else { 4e4 },
                n: n_exp,
            };
            let model = SpecimenModel::BoucWen(b);
            let sys = ForcedSpecimen::new(&model).unwrap();
            let fs = 50_000.0;
            let dt = 1.0 / fs;
            let w = 2.0 * PI * 2.0;
            let n = (1.5 * fs) as usize + 1; // three cycles of 2 Hz
            let u: Vec<f64> = (0..n).map(|j| 150.0 * (w * j as f64 * dt).sin()).collect();
            let s = simulate_held(
                &sys,
                &u,
                dt,
                &[0.0, 0.0, 0.0],
                Integrator::DormandPrince {
                    rtol: 1e-12,
                    atol: 1e-16,
                },
            )
            .unwrap();
            let (x, v, z) = (&s[0], &s[1], &s[2]);
            let work: f64 = (0..n - 1).map(|j| u[j] * (x[j + 1] - x[j])).sum();
            let k = b.stiffness_n_per_m;
            let stored = |j: usize| {
                0.5 * b.mass_kg * v[j] * v[j]
                    + 0.5 * b.alpha * k * x[j] * x[j]
                    + (1.0 - b.alpha) * k * z[j] * z[j] / (2.0 * b.a)
            };
            let rate = |j: usize| {
                let zn = z[j].abs().powf(b.n);
                b.damping_ns_per_m * v[j] * v[j]
                    + (1.0 - b.alpha) * k / b.a
                        * (b.beta_per_m_pow_n * v[j].abs() * zn * z[j].abs()
                            + b.gamma_per_m_pow_n * v[j] * z[j] * zn)
            };
            // Simpson over an even number of intervals.
            let m = (n - 1) / 2 * 2;
            let mut dissipated = rate(0) + rate(m);
            for j in 1..m {
                dissipated += if j % 2 == 1 { 4.0 } else { 2.0 } * rate(j);
            }
            dissipated *= dt / 3.0;
            let work_m: f64 = (0..m).map(|j| u[j] * (x[j + 1] - x[j])).sum();
            let balance = stored(m) - stored(0) + dissipated;
            assert!(
                work > 0.0 && dissipated > 0.1 * work_m,
                "n = {n_exp}: the loop must dissipate"
            );
            assert_relative_eq!(balance, work_m, max_relative = 1e-6);
            // The hysteretic variable stays within its bound (A / (beta + gamma))^(1/n).
            let bound = (b.a / (b.beta_per_m_pow_n + b.gamma_per_m_pow_n)).powf(1.0 / b.n);
            assert!(z.iter().all(|zz| zz.abs() <= bound * (1.0 + 1e-9)));
        }
    }

    #[test]
    fn parameter_errors_name_the_parameter() {
        let msg = |s: SpecimenModel| s.validate().unwrap_err().to_string();
        assert_eq!(
            msg(SpecimenModel::Duffing(Duffing {
                mass_kg: 0.0,
                damping_ns_per_m: 3.0,
                ..duffing()
            })),
            "duffing specimen: mass_kg must be positive and finite (got 0)"
        );
        assert_eq!(
            msg(SpecimenModel::Duffing(Duffing {
                cubic_stiffness_n_per_m3: f64::NAN,
                ..duffing()
            })),
            "duffing specimen: cubic_stiffness_n_per_m3 must be finite (got NaN)"
        );
        assert_eq!(
            msg(SpecimenModel::Friction(Friction {
                smoothing_velocity_m_per_s: -1e-3,
                ..friction()
            })),
            "friction specimen: smoothing_velocity_m_per_s must be positive and finite (got -0.001)"
        );
        assert_eq!(
            msg(SpecimenModel::Friction(Friction {
                coulomb_force_n: -5.0,
                ..friction()
            })),
            "friction specimen: coulomb_force_n must be non-negative and finite (got -5)"
        );
        let bw = BoucWen {
            mass_kg: 1.0,
            damping_ns_per_m: 1.0,
            stiffness_n_per_m: 1e4,
            alpha: 0.1,
            a: 1.0,
            beta_per_m_pow_n: 100.0,
            gamma_per_m_pow_n: 50.0,
            n: 1.0,
        };
        assert_eq!(
            msg(SpecimenModel::BoucWen(BoucWen { n: 0.5, ..bw })),
            "bouc-wen specimen: n must be finite and at least 1 (got 0.5)"
        );
        assert_eq!(
            msg(SpecimenModel::BoucWen(BoucWen { alpha: 1.5, ..bw })),
            "bouc-wen specimen: alpha must be in [0, 1] (got 1.5)"
        );
        assert_eq!(
            msg(SpecimenModel::BoucWen(BoucWen {
                gamma_per_m_pow_n: 150.0,
                ..bw
            })),
            "bouc-wen specimen: gamma_per_m_pow_n must be within [-beta_per_m_pow_n, beta_per_m_pow_n] (bounded, dissipative Bouc-Wen) (got 150)"
        );
        assert_eq!(
            msg(SpecimenModel::BoucWen(BoucWen { a: 0.0, ..bw })),
            "bouc-wen specimen: a must be positive and finite (got 0)"
        );
        assert_eq!(
            msg(SpecimenModel::LinearSdof {
                mass_kg: 3.8,
                damping_ns_per_m: -1.0,
                stiffness_n_per_m: 1e5
            }),
            "linear sdof specimen: damping_ns_per_m must be non-negative and finite (got -1)"
        );
        // A missing parameter is caught where the specimen is read, naming it.
        let e = serde_json::from_str::<SpecimenModel>(
            r#"{"kind": "friction", "mass_kg": 1.0, "damping_ns_per_m": 1.0, "stiffness_n_per_m": 1.0, "coulomb_force_n": 2.0}"#,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("missing field `smoothing_velocity_m_per_s`"),
            "{e}"
        );
        let ok: SpecimenModel = serde_json::from_str(
            r#"{"kind": "duffing", "mass_kg": 1.0, "damping_ns_per_m": 20.0, "stiffness_n_per_m": 1e4, "cubic_stiffness_n_per_m3": 7.2e5}"#,
        )
        .unwrap();
        assert_eq!(ok, SpecimenModel::Duffing(duffing()));
    }
}
