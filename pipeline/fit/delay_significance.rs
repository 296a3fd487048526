//! Whether a run's data support a pure delay its fit lacks, asked of every
//! per-run fit made without one (a press driving an unknown specimen, which
//! the joint fit cannot take).
//!
//! The fit is made again with a fitted delay, and the two are compared by
//! the extra-sum-of-squares F test the joint fit's structure selection
//! uses (`identify::joint::select`): with cost_0 the weighted cost without the
//! delay and cost_1, dof_1 with it,
//!
//!   F = (cost_0 - cost_1) / (cost_1 / dof_1),
//!
//! F(1, dof_1)-distributed when the delay is not needed. Dividing by the
//! larger fit's reduced chi-square rather than trusting the variances keeps
//! the test honest where model error remains: the delay must explain more
//! than the residual scatter left with it.

use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use super::{DelayPlan, FitError, FitInput, FitOptions, TfFit, fit};

/// The p-value below which a larger model is taken: the delay here, a
/// larger structure in the joint fit's selection.
pub const P_SIGNIFICANT: f64 = 1e-3;

/// The fit with a delay, and the F test against the fit without.
#[derive(Debug)]
pub struct DelayTest {
    /// The fit with a delay, or why there is none.
    pub with_delay: Result<TfFit, FitError>,
    /// The F statistic and its p-value, when the fit with the delay
    /// converged to a stable model.
    pub f_test: Option<(f64, f64)>,
}

impl DelayTest {
    /// Whether the data support the delay (p below [`P_SIGNIFICANT`]).
    pub fn supported(&self) -> bool {
        self.f_test.is_some_and(|(_, p)| p < P_SIGNIFICANT)
    }
}

/// The weighted cost and its degrees of freedom.
fn cost(fit: &TfFit) -> (f64, f64) {
    let dof = (2 * fit.n_bins).saturating_sub(fit.params.len()) as f64;
    (fit.reduced_chi2 * dof, dof)
}

/// `without`, fitted to `input` with `opts` and no delay, against the same
/// model with a delay of at most `max_delay_s` fitted.
pub fn delay_test(
    input: &FitInput<'_>,
    opts: &FitOptions,
    without: &TfFit,
    max_delay_s: f64,
) -> DelayTest {
    let with_opts = FitOptions {
        delay: DelayPlan::Fit { max_s: max_delay_s },
        ..opts.clone()
    };
    let with_delay = fit(input, &with_opts);
    let f_test = with_delay
        .as_ref()
        .ok()
        .filter(|w| w.converged && w.stable)
        .and_then(|w| {
            let ((c0, _), (c1, dof1)) = (cost(without), cost(w));
            let f = ((c0 - c1) / (c1 / dof1)).max(0.0);
            let p = FisherSnedecor::new(1.0, dof1).ok()?.sf(f);
            Some((f, p))
        });
    DelayTest { with_delay, f_test }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::Intersample;
    use nalgebra::Complex;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// 0.5-30 Hz, 600 bins, a 0/2 plant with 1e-3 noise per component.
    fn data(delay_s: f64, seed: u64) -> (Vec<f64>, Vec<Complex<f64>>, Vec<f64>) {
        let f: Vec<f64> = (10..=600).map(|i| i as f64 * 0.05).collect();
        let noise = Normal::new(0.0, 1e-3).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let h = f
            .iter()
            .map(|&f| {
                let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
                9000.0 / (s * s + 240.0 * s + 9000.0) * (-s * delay_s).exp()
                    + Complex::new(noise.sample(&mut rng), noise.sample(&mut rng))
            })
            .collect();
        (f.clone(), h, vec![2e-6; f.len()])
    }

    fn opts() -> FitOptions {
        let mut o = FitOptions::new(0, 2, 1000.0);
        o.intersample = Intersample::None;
        o
    }

    /// A 2 ms delay in the data: the test supports it and the fit with it
    /// finds 2 ms; none in the data: over 200 seeds it is supported about
    /// as often as the p-value threshold says (at most 2 in 200 against
    /// 0.2 expected, Poisson tail 1.8e-2), and never with the delay far
    /// from 0.
    #[test]
    fn a_delay_in_the_data_is_supported_and_none_is_not() {
        let (f, h, v) = data(0.002, 1);
        let input = FitInput {
            freq_hz: &f,
            h: &h,
            variance: &v,
        };
        let without = fit(&input, &opts()).unwrap();
        let t = delay_test(&input, &opts(), &without, 0.02);
        assert!(t.supported(), "{:?}", t.f_test);
        let d = *t.with_delay.as_ref().unwrap().params.last().unwrap();
        assert!((d / 0.002 - 1.0).abs() < 0.02, "{d}");

        let mut supported = 0;
        for seed in 0..200 {
            let (f, h, v) = data(0.0, 100 + seed);
            let input = FitInput {
                freq_hz: &f,
                h: &h,
                variance: &v,
            };
            let without = fit(&input, &opts()).unwrap();
            let t = delay_test(&input, &opts(), &without, 0.02);
            assert!(t.f_test.is_some(), "seed {seed}: {:?}", t.with_delay.err());
            supported += usize::from(t.supported());
        }
        assert!(supported <= 2, "{supported} of 200");
    }
}
