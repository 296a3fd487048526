//! The ETFE of a simulated run assembled in the frequency domain, for the
//! stiffness sensitivity's Monte Carlo: its identifications replay one
//! command and differ only by their noise.
//!
//! With a rectangular window and the mean (or nothing) taken out, the
//! transforms are linear in the signal. So the command's transforms are
//! computed once, the noiseless response's once per stiffness
//! (`EtfeSynthesis::spectra_of`), and a draw adds the DFT of white noise
//! drawn directly on the bins the fit reads (`EtfeSynthesis::white_noise`):
//! exact for the whole-record transform the ETFE and its variance read. One
//! approximation, stated: each Welch segment's bins, which only give the
//! coherence, are drawn with their own distribution but independently of
//! the other segments' and of the whole record's. The derivation:
//! docs/methods.md, "The Monte Carlo's draws".

use nalgebra::Complex;

use super::{
    Detrend, Frf, FrfError, FrfPlan, LocalFits, Method, SegmentTransform, VARIANCE_REACH_BINS,
    Window, accumulate_segment, check_inputs, coherence_of, etfe_from_transforms, to_density,
    window,
};

/// Why a plan's ETFE cannot be assembled in the frequency domain: a
/// transform that is not linear bin by bin in the noise.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unsynthesizable {
    #[error("the {0:?} estimator (only the ETFE is assembled from its transforms)")]
    Estimator(Method),
    #[error("a {0:?} window (a tapered window correlates neighbouring noise bins)")]
    Window(Window),
    #[error("linear detrending (the fitted ramp mixes the noise into every bin)")]
    LinearDetrend,
    #[error(transparent)]
    Frf(#[from] FrfError),
}

/// One signal's transforms as the ETFE reads them: the whole record's
/// bins 0 .. `keep` and each Welch segment's bins 0 .. `keep_coarse`.
#[derive(Debug, Clone, PartialEq)]
pub struct EtfeSpectra {
    pub(super) whole: Vec<Complex<f64>>,
    /// The segments' bins one segment after the other.
    pub(super) segments: Vec<Complex<f64>>,
}

/// The command's transforms and the plan's geometry, made once for every
/// simulated run it drives.
#[derive(Debug, Clone)]
pub struct EtfeSynthesis {
    n: usize,
    sample_rate_hz: f64,
    detrend: Detrend,
    segment_length: usize,
    hop: usize,
    n_segments: usize,
    /// Whole-record bins kept: those up to `max_hz` and the variance's reach.
    keep: usize,
    /// Welch bins kept: those the coherence of the kept bins interpolates.
    pub(super) keep_coarse: usize,
    /// The segments' (rectangular) window.
    w: Vec<f64>,
    u: EtfeSpectra,
    /// Whether the FRFs keep the command's DFT for a fit with the record's
    /// transient ([`FrfPlan::transient`]): all the bins it keeps.
    transient: bool,
    /// The memo of the local fits every reading's noise level makes.
    local_fits: LocalFits,
}

impl EtfeSynthesis {
    /// Whether `plan`'s ETFE is linear bin by bin in the noise, so that it
    /// can be assembled from transforms (what [`EtfeSynthesis::new`] asks
    /// of the plan before it looks at a signal).
    pub fn check_plan(plan: &FrfPlan) -> Result<(), Unsynthesizable> {
        if plan.method() != Method::Etfe {
            return Err(Unsynthesizable::Estimator(plan.method()));
        }
        if plan.window() != Window::Rectangular {
            return Err(Unsynthesizable::Window(plan.window()));
        }
        if plan.detrend() == Detrend::Linear {
            return Err(Unsynthesizable::LinearDetrend);
        }
        Ok(())
    }

    /// The synthesis of `plan`'s ETFE for runs driven by `u` sampled at
    /// `sample_rate_hz`, keeping the bins up to `max_hz` and the reach of
    /// their variance ([`VARIANCE_REACH_BINS`]), as `Frf::keep_up_to` does.
    pub fn new(
        u: &[f64],
        sample_rate_hz: f64,
        plan: &FrfPlan,
        max_hz: f64,
    ) -> Result<Self, Unsynthesizable> {
        Self::check_plan(plan)?;
        check_inputs(u, u, sample_rate_hz, plan.segment_length(), plan.overlap())?;
        let n = u.len();
        let l = plan.segment_length();
        let resolution_hz = sample_rate_hz / n as f64;
        // The bins whose frequency, computed as the ETFE computes it, is
        // at most max_hz, and the variance's reach beyond them.
        let keep = ((0..n / 2 + 1)
            .take_while(|&k| k as f64 * resolution_hz <= max_hz)
            .count()
            + VARIANCE_REACH_BINS)
            .min(n / 2 + 1);
        // The coherence at the last kept bin interpolates between two Welch
        // bins; the one above it is the last needed.
        let last_hz = (keep - 1) as f64 * resolution_hz;
        let coarse_resolution_hz = sample_rate_hz / l as f64;
        let keep_coarse = ((last_hz / coarse_resolution_hz).floor() as usize + 2).min(l / 2 + 1);
        let hop = l - (plan.overlap() * l as f64).floor() as usize;
        let mut synthesis = Self {
            n,
            sample_rate_hz,
            detrend: plan.detrend(),
            segment_length: l,
            hop,
            n_segments: (n - l) / hop + 1,
            keep,
            keep_coarse,
            w: window(Window::Rectangular, l),
            transient: plan.transient().is_some(),
            local_fits: LocalFits::default(),
            u: EtfeSpectra {
                whole: Vec::new(),
                segments: Vec::new(),
            },
        };
        synthesis.u = synthesis.spectra_of(u)?;
        Ok(synthesis)
    }

    /// The transforms of a signal of the command's length.
    pub fn spectra_of(&self, x: &[f64]) -> Result<EtfeSpectra, FrfError> {
        check_inputs(x, x, self.sample_rate_hz, self.segment_length, 0.0)?;
        if x.len() != self.n {
            return Err(FrfError::LengthMismatch {
                u_len: self.n,
                y_len: x.len(),
            });
        }
        let mut whole_transform = SegmentTransform::new(self.n);
        let mut whole = whole_transform.make_output();
        whole_transform.run(x, None, self.detrend, &mut whole);
        drop(whole_transform);
        whole.truncate(self.keep);
        let l = self.segment_length;
        let mut transform = SegmentTransform::new(l);
        let mut out = transform.make_output();
        let mut segments = Vec::with_capacity(self.n_segments * self.keep_coarse);
        for s in 0..self.n_segments {
            let start = s * self.hop;
            transform.run(&x[start..start + l], Some(&self.w), self.detrend, &mut out);
            segments.extend_from_slice(&out[..self.keep_coarse]);
        }
        Ok(EtfeSpectra { whole, segments })
    }

    /// The transforms of white Gaussian noise of std `sigma` (per sample),
    /// drawn bin by bin from `standard_normal` (the whole record's bins
    /// first, then each segment's, in order): see the module's note.
    pub fn white_noise(&self, sigma: f64, mut standard_normal: impl FnMut() -> f64) -> EtfeSpectra {
        let mut bins = |len: usize, keep: usize, out: &mut Vec<Complex<f64>>| {
            let half = sigma * (len as f64 / 2.0).sqrt();
            let full = sigma * (len as f64).sqrt();
            for k in 0..keep {
                let z = if k == 0 {
                    match self.detrend {
                        Detrend::None => Complex::new(full * standard_normal(), 0.0),
                        _ => Complex::new(0.0, 0.0),
                    }
                } else if len.is_multiple_of(2) && k == len / 2 {
                    Complex::new(full * standard_normal(), 0.0)
                } else {
                    let re = half * standard_normal();
                    Complex::new(re, half * standard_normal())
                };
                out.push(z);
            }
        };
        let mut whole = Vec::with_capacity(self.keep);
        bins(self.n, self.keep, &mut whole);
        let mut segments = Vec::with_capacity(self.n_segments * self.keep_coarse);
        for _ in 0..self.n_segments {
            bins(self.segment_length, self.keep_coarse, &mut segments);
        }
        EtfeSpectra { whole, segments }
    }

    /// The ETFE of the output `clean + noise` against the command, on the
    /// kept bins: what `estimate` gives for it, after
    /// `keep_up_to(max_hz, VARIANCE_REACH_BINS)`, but for rounding.
    pub fn frf(&self, clean: &EtfeSpectra, noise: &EtfeSpectra) -> Frf {
        let kc = self.keep_coarse;
        let (mut suu, mut syy, mut suy) = (
            vec![0.0; kc],
            vec![0.0; kc],
            vec![Complex::new(0.0, 0.0); kc],
        );
        let mut yf = vec![Complex::new(0.0, 0.0); kc];
        for s in 0..self.n_segments {
            let at = s * kc..(s + 1) * kc;
            for ((y, c), e) in yf
                .iter_mut()
                .zip(&clean.segments[at.clone()])
                .zip(&noise.segments[at.clone()])
            {
                *y = c + e;
            }
            accumulate_segment(&self.u.segments[at], &yf, (&mut suu, &mut syy, &mut suy));
        }
        to_density(
            (&mut suu, &mut syy, &mut suy),
            self.sample_rate_hz,
            &self.w,
            self.n_segments,
        );
        let coherence = coherence_of(&suu, &syy, &suy);
        let y = clean
            .whole
            .iter()
            .zip(&noise.whole)
            .map(|(c, e)| c + e)
            .collect();
        let mut frf = etfe_from_transforms(
            self.u.whole.clone(),
            y,
            self.n,
            1.0 / (self.sample_rate_hz * self.n as f64),
            self.sample_rate_hz,
            &coherence,
            self.sample_rate_hz / self.segment_length as f64,
        );
        frf.input_dft = self.transient.then(|| self.u.whole.clone());
        // Every reading shares the command's Suu, so its local fits' normal
        // matrices: one memo serves them all.
        frf.local_fits = self.local_fits.clone();
        frf
    }
}
