//! The servo-valve's flow-pressure law (Merritt, Hydraulic Control Systems,
//! ch. 5; docs/model.md): the flow reaching the chamber is
//! r sqrt(1 - sign(r) f / F_max), F_max = A P_s, where Eq. 10 has r. On a
//! sinusoid its fundamental is N r with N the describing function of the
//! force amplitude over F_max and the phase between flow and force
//! ([`flow_gain`]). N multiplies the valve's flow inside the loop, so with
//! D = (s + beta1) Q + a1b0 (Eqs. 12-17) x1/u becomes
//! a1b0 N / ((s + beta1) Q + a1b0 N) ([`flow_factor`]): the equivalent
//! linear rig at a run's load.

use std::sync::OnceLock;

use nalgebra::Complex;

/// Gauss-Legendre nodes on (-pi/2, pi/2), by rho: the half-cycle
/// integrand of [`flow_gain`] is analytic there for rho < 1, its nearest
/// singularity acosh(1 / rho) off the real axis, d. Scaled to (-1, 1)
/// (d' = 2 d / pi) the error falls as r^(-2n), r = d' + sqrt(1 + d'^2) the
/// Bernstein ellipse's: at rho = 0.35 (d = 1.76, r = 2.6) 16 nodes give
/// 1e-13, at 0.7 (d = 0.90, r = 1.77) 32 give 1e-16 and at 0.95 (d =
/// 0.32, r = 1.22) 64 give 1e-11. Most bins' rho are small.
const NODES: [(f64, usize); 3] = [(0.35, 16), (0.7, 32), (1.0, 64)];

/// The describing function N of the flow-pressure law and its derivatives
/// with respect to rho and phi.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowGain {
    pub n: Complex<f64>,
    pub d_rho: Complex<f64>,
    pub d_phi: Complex<f64>,
}

/// The fundamental of r sqrt(1 - sign(r) f / F_max) over r's, for
/// r = R cos t and f = F cos(t - phi) (the force lagging the flow by phi),
/// rho = F / F_max < 1: N = (1/pi) int_0^2pi cos t sqrt(1 - sign(cos t)
/// rho cos(t - phi)) e^{-jt} dt. The half-cycle where r < 0 is the other
/// half shifted by pi (both cosines change sign, and so does e^{-jt}), so
/// N is twice the integral over (-pi/2, pi/2), where the root is smooth.
/// To first order N = 1 - (rho / pi)(e^{-j phi} + e^{j phi} / 3): a loss in
/// phase with the flow and a lead or lag in quadrature. None at rho >= 1,
/// where the valve passes no flow against the load for part of the cycle.
pub fn flow_gain(rho: f64, phi: f64) -> Option<FlowGain> {
    if !(0.0..1.0).contains(&rho) || !phi.is_finite() {
        return None;
    }
    let (sin_phi, cos_phi) = phi.sin_cos();
    let (mut n, mut d_rho, mut d_phi) =
        (Complex::default(), Complex::default(), Complex::default());
    for node in half_cycle(rho) {
        // cos(t - phi) and sin(t - phi) from t's, tabled, and phi's.
        let cos_lag = node.cos * cos_phi + node.sin * sin_phi;
        let sin_lag = node.sin * cos_phi - node.cos * sin_phi;
        let root = (1.0 - rho * cos_lag).sqrt();
        n += node.e * root;
        d_rho += node.e * (-0.5 * cos_lag / root);
        d_phi += node.e * (-0.5 * rho * sin_lag / root);
    }
    Some(FlowGain { n, d_rho, d_phi })
}

/// N alone, as [`flow_gain`] gives it: what the fixed point of
/// [`loaded_gain`] iterates on.
fn flow_n(rho: f64, phi: f64) -> Option<Complex<f64>> {
    if !(0.0..1.0).contains(&rho) || !phi.is_finite() {
        return None;
    }
    let (sin_phi, cos_phi) = phi.sin_cos();
    Some(half_cycle(rho).iter().fold(Complex::default(), |n, node| {
        n + node.e * (1.0 - rho * (node.cos * cos_phi + node.sin * sin_phi)).sqrt()
    }))
}

/// A node of the half-cycle's quadrature: sin t, cos t and the weight
/// times cos t e^{-jt}, the integrand's part that does not depend on rho
/// or phi.
struct Node {
    sin: f64,
    cos: f64,
    e: Complex<f64>,
}

/// The [`NODES`] rule for `rho` on (-pi/2, pi/2) with what [`flow_gain`]
/// needs of t at each node, computed once: (2 / pi) int over
/// (-pi/2, pi/2), whose Jacobian from (-1, 1) is pi/2.
fn half_cycle(rho: f64) -> &'static [Node] {
    static TABLES: OnceLock<Vec<Vec<Node>>> = OnceLock::new();
    let tables = TABLES.get_or_init(|| {
        NODES
            .iter()
            .map(|&(_, n)| {
                let (nodes, weights) = gauss_legendre(n);
                nodes
                    .iter()
                    .zip(&weights)
                    .map(|(&x, &w)| {
                        let (sin, cos) = (std::f64::consts::FRAC_PI_2 * x).sin_cos();
                        Node {
                            sin,
                            cos,
                            e: Complex::new(cos, -sin) * (w * cos),
                        }
                    })
                    .collect()
            })
            .collect()
    });
    let k = NODES
        .iter()
        .position(|&(top, _)| rho <= top)
        .unwrap_or(NODES.len() - 1);
    &tables[k]
}

/// The factor the flow-pressure law puts on x1/u at `s` = j w for a load
/// `sp` on the piston (the specimen's S(s) = m s^2 + c s + k, and whatever
/// else the chamber's force drives) moving with displacement amplitude
/// `amplitude_m`: with Q = (s + a3) S + a2 s, D = (s + beta1) Q + a1b0 and
/// N at rho = |S| X / F_max and the flow's lead over the force
/// phi = arg(Q / (N S)) (N found with phi, by fixed-point iteration),
/// x1/u = a1b0 N / ((s + beta1) Q + a1b0 N), which is Eq. 17's times
/// D N / ((s + beta1) Q + a1b0 N). None where the force reaches F_max; 1
/// without a load (f = 0: the law has nothing to act on).
pub fn flow_factor(
    rig: &super::RigParams,
    s: Complex<f64>,
    sp: Complex<f64>,
    amplitude_m: f64,
    max_force_n: f64,
) -> Option<Complex<f64>> {
    let one = Complex::new(1.0, 0.0);
    if sp.norm() == 0.0 || amplitude_m == 0.0 {
        return Some(one);
    }
    let q = (s + rig.a3_per_s) * sp + s * rig.a2_n_per_m;
    let n = loaded_gain(q / sp, sp.norm() * amplitude_m / max_force_n)?.n;
    let sbq = (s + rig.beta1_per_s) * q;
    let a = rig.a1b0_n_per_m_s2;
    Some((sbq + a) * n / (sbq + a * n))
}

/// The linear rig (Eq. 10) nearest the rig at a run's load: the rig whose
/// x1/u with `specimen`, a1b0 / ((s + beta1) Q + a1b0), is closest in
/// log magnitude and phase to the law's ([`flow_factor`] at displacement
/// amplitude `amplitude_m`) at the frequencies `freqs_hz`, by Gauss-Newton
/// on the four log-parameters from `rig` (the residual is nearly nil, so
/// a few steps converge). One specimen's x1/u does not fix all four (a
/// spring's has three coefficients, which is why Eqs. 18-20 take two
/// springs): a ridge of 1e-10 of J^T J's trace toward `rig` picks, among
/// the rigs that fit, the one nearest the zero-load rig in log-parameters.
/// What linear tools (a compensator, a tracking prediction) take for the
/// rig at that load. None where the force reaches F_max at a frequency, or
/// the steps do not settle to 1e-8 of each parameter.
pub fn equivalent_rig(
    rig: &super::RigParams,
    specimen: &super::LinearSpecimen,
    amplitude_m: f64,
    max_force_n: f64,
    freqs_hz: &[f64],
) -> Option<super::RigParams> {
    let (m, c, k) = specimen.mck();
    let at = |f: f64| {
        let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
        (s, m * s * s + c * s + k)
    };
    // x1/u of the rig at its load, the target.
    let target: Vec<Complex<f64>> = freqs_hz
        .iter()
        .map(|&f| {
            let (s, sp) = at(f);
            Some(linear_x1_u(rig, s, sp) * flow_factor(rig, s, sp, amplitude_m, max_force_n)?)
        })
        .collect::<Option<_>>()?;
    let theta0 = nalgebra::Vector4::new(
        rig.beta1_per_s.ln(),
        rig.a1b0_n_per_m_s2.ln(),
        rig.a2_n_per_m.ln(),
        rig.a3_per_s.ln(),
    );
    let mut theta = theta0;
    let of = |t: &nalgebra::Vector4<f64>| super::RigParams {
        beta1_per_s: t[0].exp(),
        a1b0_n_per_m_s2: t[1].exp(),
        a2_n_per_m: t[2].exp(),
        a3_per_s: t[3].exp(),
        p_gain: rig.p_gain,
    };
    for _ in 0..50 {
        let x = of(&theta);
        let mut jtj = nalgebra::Matrix4::<f64>::zeros();
        let mut jtr = nalgebra::Vector4::<f64>::zeros();
        for (&f, &want) in freqs_hz.iter().zip(&target) {
            let (s, sp) = at(f);
            let q = (s + x.a3_per_s) * sp + s * x.a2_n_per_m;
            let d = (s + x.beta1_per_s) * q + x.a1b0_n_per_m_s2;
            // d ln H / d ln p for H = a1b0 / D.
            let grad = [
                -x.beta1_per_s * q / d,
                1.0 - x.a1b0_n_per_m_s2 / d,
                -(s + x.beta1_per_s) * s * x.a2_n_per_m / d,
                -(s + x.beta1_per_s) * sp * x.a3_per_s / d,
            ];
            // The log of the ratio, which stays near 1: no branch cut.
            let r = (linear_x1_u(&x, s, sp) / want).ln();
            for i in 0..4 {
                jtr[i] += (grad[i].conj() * r).re;
                for j in 0..4 {
                    jtj[(i, j)] += (grad[i].conj() * grad[j]).re;
                }
            }
        }
        let ridge = 1e-10 * jtj.trace();
        let step = (jtj + nalgebra::Matrix4::<f64>::identity() * ridge)
            .cholesky()?
            .solve(&(-(jtr + (theta - theta0) * ridge)));
        theta += step;
        // 1e-8 of each parameter: below it the steps wander at the level
        // the describing function's fixed point is solved to.
        if step.amax() < 1e-8 {
            return Some(of(&theta));
        }
    }
    None
}

/// The rig a linear tool (a compensator, a tracking prediction) builds its
/// plant on for a specimen: Eq. 10's rig, or with the valve's flow law its
/// equivalent at the load the specimen takes at the run's displacement
/// amplitude ([`equivalent_rig`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RigAtLoad {
    /// The zero-load rig.
    pub rig: super::RigParams,
    pub law: Option<LoadLaw>,
}

/// Where a [`RigAtLoad`] takes the flow law: F_max, the displacement
/// amplitude the load is taken at and the band's frequencies the
/// equivalent rig is fitted over.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadLaw {
    pub max_force_n: f64,
    pub amplitude_m: f64,
    pub freqs_hz: Vec<f64>,
}

impl RigAtLoad {
    /// The rig with no flow law: the same for every specimen.
    pub fn zero_load(rig: super::RigParams) -> Self {
        RigAtLoad { rig, law: None }
    }

    /// The rig at `specimen`'s load; None where that load reaches F_max
    /// within the band (the valve passes no flow against it).
    pub fn for_specimen(&self, specimen: &super::LinearSpecimen) -> Option<super::RigParams> {
        match &self.law {
            None => Some(self.rig),
            Some(l) => equivalent_rig(
                &self.rig,
                specimen,
                l.amplitude_m,
                l.max_force_n,
                &l.freqs_hz,
            ),
        }
    }

    /// The largest force over F_max that `specimen` takes over the band at
    /// the amplitude, |S(j w)| X / F_max; None without the law.
    pub fn load_fraction(&self, specimen: &super::LinearSpecimen) -> Option<f64> {
        let l = self.law.as_ref()?;
        let (m, c, k) = specimen.mck();
        let peak = l.freqs_hz.iter().fold(0.0_f64, |p, &f| {
            let w = 2.0 * std::f64::consts::PI * f;
            p.max(Complex::new(k - m * w * w, c * w).norm())
        });
        Some(peak * l.amplitude_m / l.max_force_n)
    }
}

/// Eq. 17's x1/u at `s` for the piston's load `sp`:
/// a1b0 / ((s + beta1) ((s + a3) S + a2 s) + a1b0).
fn linear_x1_u(rig: &super::RigParams, s: Complex<f64>, sp: Complex<f64>) -> Complex<f64> {
    let q = (s + rig.a3_per_s) * sp + s * rig.a2_n_per_m;
    rig.a1b0_n_per_m_s2 / ((s + rig.beta1_per_s) * q + rig.a1b0_n_per_m_s2)
}

/// N where the flow leads the force by arg(`q_over_s` / N), with its
/// partial derivatives there: the fixed point of
/// phi -> arg(q_over_s) - arg(N(rho, phi)), a contraction whose slope
/// |dN/dphi| / |N| is about 2 rho / (3 pi).
pub fn loaded_gain(q_over_s: Complex<f64>, rho: f64) -> Option<FlowGain> {
    let base = q_over_s.arg();
    let mut n = flow_n(rho, base)?;
    for _ in 0..100 {
        let next = flow_n(rho, base - n.arg())?;
        let done = (next - n).norm() < 1e-14;
        n = next;
        if done {
            break;
        }
    }
    flow_gain(rho, base - n.arg())
}

/// The change of the loaded gain N (at its fixed point, `gain`) when rho
/// changes by `d_rho` and arg(Q / S) by `d_phi0`: dN = N_rho d_rho +
/// N_phi (d_phi0 - Im(dN / N)), solved for dN's two real parts.
pub fn loaded_change(gain: &FlowGain, d_rho: f64, d_phi0: f64) -> Complex<f64> {
    let n = gain.n;
    let c = gain.d_rho * d_rho + gain.d_phi * d_phi0;
    // dN = N (a + j b): N a + (j N + N_phi) b = c.
    let col_b = Complex::new(0.0, 1.0) * n + gain.d_phi;
    let det = n.re * col_b.im - n.im * col_b.re;
    let a = (c.re * col_b.im - c.im * col_b.re) / det;
    let b = (n.re * c.im - n.im * c.re) / det;
    n * Complex::new(a, b)
}

/// Gauss-Legendre nodes and weights on (-1, 1), scaled by 2/pi * pi/2 = 1
/// (the half-cycle's interval and N's (2 / pi) cancel): Newton's iteration
/// on P_n from Chebyshev's estimates (Golub & Welsch give the same).
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n.div_ceil(2) {
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            // P_n(z) by the three-term recurrence, and P_n'(z).
            let (mut p0, mut p1) = (1.0, z);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * z * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (z * p1 - p0) / (z * z - 1.0);
            let step = p1 / dp;
            z -= step;
            if step.abs() < 1e-15 {
                break;
            }
        }
        let weight = 2.0 / ((1.0 - z * z) * dp * dp);
        x[i] = -z;
        x[n - 1 - i] = z;
        w[i] = weight;
        w[n - 1 - i] = weight;
    }
    (x, w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The equivalent rig of the paper's rig with its first spring at 4 mm
    /// over 0.5-30 Hz: at F_max far beyond the force it is the rig itself;
    /// at the ShoreWestern's 4.94 kN (the spring's 467 N is 9.4 % of it)
    /// its x1/u departs from the law's by under half of what the zero-load
    /// rig's does, RMS over the band (about a third: the law's phase lead
    /// in quadrature, 2 rho / (3 pi) at every frequency, is no linear
    /// rig's), and its a3 is higher (the law's first-order term is a
    /// leakage, -|r| f / (2 F_max)).
    #[test]
    fn the_equivalent_rig_is_the_rig_at_its_load() {
        let rig = crate::model::PAPER_RIG;
        let spring = crate::model::LinearSpecimen::Spring {
            stiffness_n_per_m: 116_640.0,
        };
        let freqs: Vec<f64> = (0..120)
            .map(|i| 0.5 * 60f64.powf(i as f64 / 119.0))
            .collect();
        let same = equivalent_rig(&rig, &spring, 4e-3, 1e12, &freqs).expect("settles");
        for (a, b) in [
            (same.beta1_per_s, rig.beta1_per_s),
            (same.a1b0_n_per_m_s2, rig.a1b0_n_per_m_s2),
            (same.a2_n_per_m, rig.a2_n_per_m),
            (same.a3_per_s, rig.a3_per_s),
        ] {
            assert!((a / b - 1.0).abs() < 1e-8, "{a} against {b}");
        }
        let fmax = 2.387e-4 * 2.07e7;
        let eq = equivalent_rig(&rig, &spring, 4e-3, fmax, &freqs).expect("settles");
        // RMS relative departures from the law's x1/u over the band.
        let (mut eq_sq, mut zero_sq) = (0.0, 0.0);
        for &f in &freqs {
            let s = Complex::new(0.0, 2.0 * PI * f);
            let sp = Complex::new(116_640.0, 0.0);
            let loaded = linear_x1_u(&rig, s, sp) * flow_factor(&rig, s, sp, 4e-3, fmax).unwrap();
            eq_sq += (linear_x1_u(&eq, s, sp) / loaded - 1.0).norm_sqr();
            zero_sq += (linear_x1_u(&rig, s, sp) / loaded - 1.0).norm_sqr();
        }
        let n = freqs.len() as f64;
        let (eq_rms, zero_rms) = ((eq_sq / n).sqrt(), (zero_sq / n).sqrt());
        eprintln!("{eq:?}: RMS {eq_rms:.2e}, zero-load {zero_rms:.2e}");
        assert!(zero_rms > 0.01, "{zero_rms}");
        assert!(eq_rms < 0.5 * zero_rms, "{eq_rms} against {zero_rms}");
        assert!(eq.a3_per_s > rig.a3_per_s);
    }

    /// N by brute force over the whole cycle, the sign function and all: the
    /// fundamental of the sampled r sqrt(1 - sign(r) f / F_max) (a Riemann
    /// sum of 2^20 points, exact for a trigonometric polynomial and within
    /// 1e-10 here, where the integrand has kinks only at r = 0 and is
    /// continuous there).
    fn brute(rho: f64, phi: f64) -> Complex<f64> {
        let m = 1 << 20;
        let mut sum = Complex::default();
        for i in 0..m {
            let t = 2.0 * PI * i as f64 / m as f64;
            let r = t.cos();
            let f = rho * (t - phi).cos();
            let y = r * (1.0 - r.signum() * f).sqrt();
            sum += Complex::new(t.cos(), -t.sin()) * y;
        }
        sum * (2.0 / m as f64)
    }

    #[test]
    fn the_describing_function_is_the_fundamental_of_the_law() {
        for &(rho, phi) in &[
            (0.05, 0.3),
            (0.3, 1.2),
            (0.3, -0.7),
            (0.35, 1.0),
            (0.6, PI / 2.0),
            (0.7, 0.4),
            (0.9, 2.5),
            (0.95, PI / 2.0),
        ] {
            let n = flow_gain(rho, phi).unwrap().n;
            let want = brute(rho, phi);
            assert!(
                (n - want).norm() < 1e-9,
                "rho {rho}, phi {phi}: {n} vs {want}"
            );
        }
        assert!((flow_gain(0.0, 0.4).unwrap().n - 1.0).norm() < 1e-14);
        assert!(flow_gain(1.0, 0.0).is_none());
    }

    /// To first order in rho, N = 1 - (rho / pi)(e^{-j phi} + e^{j phi} / 3)
    /// (the fundamental of |cos t| cos(t - phi), from |cos t|'s Fourier
    /// series 2/pi + (4 / 3 pi) cos 2t + ...): the second-order remainder
    /// is within rho^2 / 4.
    #[test]
    fn at_small_loads_the_gain_is_the_first_order_term() {
        for &phi in &[0.0, 0.8, PI / 2.0, 2.0, -1.1] {
            let rho = 1e-3;
            let n = flow_gain(rho, phi).unwrap().n;
            let first = Complex::new(1.0, 0.0)
                - (Complex::from_polar(1.0, -phi) + Complex::from_polar(1.0, phi) / 3.0)
                    * (rho / PI);
            assert!(
                (n - first).norm() < rho * rho / 4.0,
                "phi {phi}: {n} vs {first}"
            );
        }
    }

    #[test]
    fn the_derivatives_are_the_gains_slopes() {
        let (rho, phi) = (0.4, 1.1);
        let g = flow_gain(rho, phi).unwrap();
        let h = 1e-6;
        let by_rho =
            (flow_gain(rho + h, phi).unwrap().n - flow_gain(rho - h, phi).unwrap().n) / (2.0 * h);
        let by_phi =
            (flow_gain(rho, phi + h).unwrap().n - flow_gain(rho, phi - h).unwrap().n) / (2.0 * h);
        assert!((g.d_rho - by_rho).norm() < 1e-8, "{} vs {by_rho}", g.d_rho);
        assert!((g.d_phi - by_phi).norm() < 1e-8, "{} vs {by_phi}", g.d_phi);
    }

    /// The loaded gain is the fixed point: N(rho, arg(Q/S) - arg N) = N.
    #[test]
    fn the_loaded_gain_is_consistent_with_its_phase() {
        let q_over_s = Complex::from_polar(3.0, 1.3);
        let n = loaded_gain(q_over_s, 0.5).unwrap().n;
        let again = flow_gain(0.5, q_over_s.arg() - n.arg()).unwrap().n;
        assert!((n - again).norm() < 1e-12, "{n} vs {again}");
        assert!(loaded_gain(q_over_s, 1.2).is_none());
    }

    /// The loaded gain's change is its finite difference.
    #[test]
    fn the_loaded_gains_change_is_its_slope() {
        let (q_over_s, rho) = (Complex::from_polar(2.0, 1.0), 0.35);
        let gain = loaded_gain(q_over_s, rho).unwrap();
        let h = 1e-6;
        let by_rho = (loaded_gain(q_over_s, rho + h).unwrap().n
            - loaded_gain(q_over_s, rho - h).unwrap().n)
            / (2.0 * h);
        let turned = |d: f64| q_over_s * Complex::from_polar(1.0, d);
        let by_phi = (loaded_gain(turned(h), rho).unwrap().n
            - loaded_gain(turned(-h), rho).unwrap().n)
            / (2.0 * h);
        let d_rho = loaded_change(&gain, 1.0, 0.0);
        let d_phi = loaded_change(&gain, 0.0, 1.0);
        assert!((d_rho - by_rho).norm() < 1e-7, "{d_rho} vs {by_rho}");
        assert!((d_phi - by_phi).norm() < 1e-7, "{d_phi} vs {by_phi}");
    }
}
