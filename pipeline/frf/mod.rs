//! Frequency-response estimation from uniformly sampled logs: Welch-averaged
//! H1 and H2 estimates, the empirical transfer-function estimate (ETFE), their
//! auto- and cross-spectral densities, ordinary coherence, the random-error
//! variance the fit stage weights by, and the bin mask it fits on.
//!
//! Conventions (Bendat & Piersol, *Random Data*, 4th ed., 2010, Ch. 5 and 9):
//! the cross-spectrum is `Suy = conj(U) Y`, H1 = Suy/Suu (noise on the output),
//! H2 = Syy/Syu with Syu = conj(Suy) (noise on the input), coherence
//! |Suy|^2/(Suu Syy). Densities are one-sided (unit^2/Hz) and scaled by the
//! window's power, so that the sum of `suu * resolution_hz` over all bins is
//! the variance of the (detrended) signal (Parseval).

use nalgebra::Complex;
use rayon::prelude::*;
use std::sync::Arc;

use realfft::RealToComplex;

mod choice;
pub mod linearity;
mod lines;
mod local_fits;
mod lpm;
pub mod periodic;
mod settings;
mod sweep;
mod synthesis;

pub use choice::{
    DEFAULT_OVERLAP, DEFAULT_SEGMENT_LENGTH, Ends, Excitation, FrfChoice, FrfRequest, MIN_PERIODS,
    describe, excitation,
};
pub use linearity::{Linearity, SlowCubic, SpringForce, linearity, slow_cubic, spring_force};
pub use lines::{at_lines, sparse_lines};
pub use local_fits::LocalFits;
use local_fits::etfe_local_noise_densities;
pub use settings::{Detrend, Estimator, FrfPlan, Method, Window};
pub use sweep::{SweepAmplitude, sweep_amplitude};
pub use synthesis::{EtfeSpectra, EtfeSynthesis, Unsynthesizable};

/// Shortest Welch segment accepted (the manifest enforces the same bound).
pub const MIN_SEGMENT_LENGTH: usize = 16;

/// A frequency-response estimate on the bins 0 ..= fs/2.
#[derive(Debug, Clone, PartialEq)]
pub struct Frf {
    /// Bin frequencies (Hz), 0 .. fs/2 in steps of `resolution_hz`.
    pub freq_hz: Vec<f64>,
    /// The estimate at each bin (0 where its denominator is exactly zero).
    pub h: Vec<Complex<f64>>,
    /// Ordinary coherence in [0, 1] at each bin (0 where undefined). For the
    /// ETFE it comes from a Welch estimate over the plan's segments,
    /// interpolated onto the ETFE's finer grid (see [`Method::Etfe`]).
    pub coherence: Vec<f64>,
    /// One-sided auto-spectral density of u (unit^2/Hz).
    pub suu: Vec<f64>,
    /// One-sided auto-spectral density of y (unit^2/Hz).
    pub syy: Vec<f64>,
    /// One-sided cross-spectral density conj(U) Y (unit^2/Hz).
    pub suy: Vec<Complex<f64>>,
    /// Welch segments averaged (1 for the ETFE).
    pub n_averages: usize,
    /// Equivalent number of independent averages after Welch's overlap
    /// correction (equal to `n_averages` without overlap; 1 for the ETFE).
    /// [`h_variance`] uses it.
    pub effective_averages: f64,
    /// The estimator that made it.
    pub method: Method,
    /// Bin spacing (Hz): fs / segment_length, or fs / record length for the ETFE.
    pub resolution_hz: f64,
    /// The per-component variance of `h` at each bin where the estimator
    /// computes it with the estimate (the LPM; infinite where it cannot),
    /// else None and [`h_variance_at`] derives it.
    pub variance: Option<Vec<f64>>,
    /// The command's DFT at each bin (the whole record's transform, as
    /// realfft gives it), kept when the plan fits the record's transient
    /// ([`FrfPlan::transient`]), whose columns divide by it.
    pub input_dft: Option<Vec<Complex<f64>>>,
    /// The memo of the ETFE noise level's local fits (not part of the
    /// value: see [`LocalFits`]).
    pub local_fits: LocalFits,
}

/// Why an FRF cannot be estimated from the given signals and settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrfError {
    #[error("u and y differ in length: u has {u_len} samples, y has {y_len}")]
    LengthMismatch { u_len: usize, y_len: usize },
    #[error("log too short: {samples} samples, segment_length {segment_length}")]
    TooShort {
        samples: usize,
        segment_length: usize,
    },
    #[error("{signal} sample {index} is not finite ({value})")]
    NonFinite {
        signal: &'static str,
        index: usize,
        value: f64,
    },
    #[error("sample rate must be finite and positive (got {0} Hz)")]
    BadSampleRate(f64),
    #[error("overlap must be in [0, 1) (got {0})")]
    BadOverlap(f64),
    #[error("segment_length must be at least {MIN_SEGMENT_LENGTH} (got {0})")]
    SegmentTooShort(usize),
    #[error(
        "the record of {record_s:.3} s cannot resolve the band's lowest frequency {lo_hz} Hz (identification.band_hz): it needs at least {need_s:.3} s ({MIN_PERIODS} periods); raise the band's lower edge to at least {:.3} Hz or record longer", MIN_PERIODS / record_s
    )]
    BandBelowResolution {
        record_s: f64,
        lo_hz: f64,
        need_s: f64,
    },
}

/// One output of a command to estimate the FRF to: its samples, as long as
/// the command, and the plan that estimates it.
#[derive(Debug, Clone, Copy)]
pub struct Output<'a> {
    pub y: &'a [f64],
    pub plan: &'a FrfPlan,
}

/// The bins an estimate keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Keep {
    /// Every bin, 0 ..= fs/2.
    All,
    /// The bins [`Frf::keep_up_to`]`(hz, extra_bins)` keeps, to the bit
    /// those of the whole estimate. A whole-record estimate forms no others
    /// (above 35 Hz, 93 % of a 1-kHz record's bins), which saves their pass
    /// and their memory.
    UpTo { hz: f64, extra_bins: usize },
}

/// One output's FRF, as [`estimate`] gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// The estimate on the bins the request keeps.
    pub frf: Frf,
    /// The input's one-sided density summed over every bin of the whole
    /// estimate but DC, in bin order, whatever bins are kept: the
    /// denominator of a band's share of the input's power.
    pub input_total: f64,
}

/// Estimates the FRF of the command `u` to each of `outputs`, each with its
/// own plan, keeping the bins `keep` says. Each output's estimate is the
/// same bits as made alone. Where every plan is the same whole-record
/// estimate but for the transient (a run's displacement and force), the
/// command's whole-record transform and its coherence segments' transforms
/// are made once for all of them.
///
/// The result is the same bits for the same input on the same machine,
/// whatever the thread count: Welch segments are accumulated in order on one
/// thread, and the passes split across threads compute each bin on its own.
/// rustfft picks its AVX, SSE or scalar kernels at run time, so a machine
/// with another instruction set may differ in the last bits.
pub fn estimate(
    u: &[f64],
    outputs: &[Output<'_>],
    sample_rate_hz: f64,
    keep: Keep,
) -> Result<Vec<Estimate>, FrfError> {
    Ok(estimate_sharing(u, outputs, sample_rate_hz, keep, false)?.0)
}

/// Each output's estimate, and the command's whole transform where
/// [`estimate_sharing`] gives it.
pub type Sharing = (Vec<Estimate>, Option<Vec<Complex<f64>>>);

/// [`estimate`], and with `share` the command's whole one-sided DFT less
/// its mean where the estimate made it (a whole-record plan, its window
/// rectangular and its detrending the mean's): the transform the
/// tracking's cross-correlation reads (`tracking::Reference::with_spectrum`),
/// made once for both.
pub fn estimate_sharing(
    u: &[f64],
    outputs: &[Output<'_>],
    sample_rate_hz: f64,
    keep: Keep,
    share: bool,
) -> Result<Sharing, FrfError> {
    // One plan for all (but the transient): a whole-record plan shares
    // the command's transforms.
    let shared = outputs
        .first()
        .map(|o| o.plan)
        .filter(|first| outputs.iter().all(|o| o.plan.same_but_transient(first)))
        .filter(|plan| !plan.method().is_welch());
    if shared.is_some() {
        return whole_record(u, outputs, sample_rate_hz, keep, share);
    }
    let estimates = outputs
        .iter()
        .map(|o| {
            if !o.plan.method().is_welch() {
                let (mut one, _) =
                    whole_record(u, std::slice::from_ref(o), sample_rate_hz, keep, false)?;
                return Ok(one.pop().expect("one estimate for one output"));
            }
            let mut frf = welch(u, o.y, sample_rate_hz, o.plan)?;
            let input_total = frf.suu.iter().skip(1).sum();
            if let Keep::UpTo { hz, extra_bins } = keep {
                frf.keep_up_to(hz, extra_bins);
            }
            Ok(Estimate { frf, input_total })
        })
        .collect::<Result<_, FrfError>>()?;
    Ok((estimates, None))
}

/// [`estimate`] of the one output `y`, every bin kept.
pub fn estimate_one(
    u: &[f64],
    y: &[f64],
    sample_rate_hz: f64,
    plan: &FrfPlan,
) -> Result<Frf, FrfError> {
    let mut one = estimate(u, &[Output { y, plan }], sample_rate_hz, Keep::All)?;
    Ok(one.pop().expect("one estimate for one output").frf)
}

/// The Welch-averaged FRF of a plan of [`Method::H1`] or [`Method::H2`].
fn welch(u: &[f64], y: &[f64], sample_rate_hz: f64, plan: &FrfPlan) -> Result<Frf, FrfError> {
    let segment_length = plan.segment_length();
    check_inputs(u, y, sample_rate_hz, segment_length, plan.overlap())?;
    let segments = Segmenting {
        length: segment_length,
        overlap: plan.overlap(),
        window_kind: plan.window(),
        detrend_kind: plan.detrend(),
    };
    let spectra = welch_spectra(u, y, sample_rate_hz, &segments);
    let method = plan.method();
    let h = spectra
        .suu
        .iter()
        .zip(&spectra.syy)
        .zip(&spectra.suy)
        .map(|((&suu, &syy), &suy)| match method {
            Method::H2 => ratio(Complex::new(syy, 0.0), suy.conj()),
            _ => ratio(suy, Complex::new(suu, 0.0)),
        })
        .collect();
    let coherence = coherence_of(&spectra.suu, &spectra.syy, &spectra.suy);
    let resolution_hz = sample_rate_hz / segment_length as f64;
    Ok(Frf {
        freq_hz: bin_frequencies(spectra.suu.len(), resolution_hz),
        h,
        coherence,
        suu: spectra.suu,
        syy: spectra.syy,
        suy: spectra.suy,
        n_averages: spectra.n_segments,
        effective_averages: spectra.effective_averages,
        method,
        resolution_hz,
        variance: None,
        input_dft: None,
        local_fits: LocalFits::default(),
    })
}

/// The whole-record estimate ([`Method::Etfe`], [`Method::Lpm`]) from `u`
/// to each of `outputs` (at least one), whose plans differ at most in the
/// transient ([`FrfPlan::transient`]: the command's transform kept in
/// [`Frf::input_dft`] up to that frequency and [`VARIANCE_REACH_BINS`]
/// beyond). The command's whole-record transform, its coherence segments'
/// and the input's summed density are made once, and each output's
/// estimate is the one it would get alone, to the bit. With `share`, the
/// command's transform as [`estimate_sharing`] gives it.
fn whole_record(
    u: &[f64],
    outputs: &[Output<'_>],
    sample_rate_hz: f64,
    keep: Keep,
    share: bool,
) -> Result<Sharing, FrfError> {
    let plan = outputs[0].plan;
    let (window_kind, detrend_kind) = (plan.window(), plan.detrend());
    let (coherence_segment_length, coherence_overlap) = (plan.segment_length(), plan.overlap());
    let lpm = plan.method() == Method::Lpm;
    for o in outputs {
        check_inputs(
            u,
            o.y,
            sample_rate_hz,
            coherence_segment_length,
            coherence_overlap,
        )?;
    }
    let n = u.len();
    // A rectangular window is not materialised: n ones would be 8n bytes of
    // fresh memory for nothing, and first touches of fresh pages are a large
    // part of this function's cost on a long record.
    let w = (window_kind != Window::Rectangular).then(|| window(window_kind, n));
    let energy = w
        .as_ref()
        .map_or(n as f64, |w| w.iter().map(|v| v * v).sum());
    let scale = 1.0 / (sample_rate_hz * energy);
    let segments = Segmenting {
        length: coherence_segment_length,
        overlap: coherence_overlap,
        window_kind,
        detrend_kind,
    };

    // The whole-record transforms and the Welch pass for the coherence are
    // independent: run them side by side (each with its own plan; the
    // arithmetic, and so every bit of the result, is the same as in series).
    let transform_of = |x: &[f64]| {
        let mut transform = SegmentTransform::new(n);
        let mut out = transform.make_output();
        transform.run(x, w.as_deref(), detrend_kind, &mut out);
        out
    };
    let ys: Vec<&[f64]> = outputs.iter().map(|o| o.y).collect();
    let ((mut u_dft, y_dfts), coarse) = rayon::join(
        || {
            rayon::join(
                || transform_of(u),
                || ys.par_iter().map(|y| transform_of(y)).collect::<Vec<_>>(),
            )
        },
        || welch_spectra_many(u, &ys, sample_rate_hz, &segments),
    );
    let input_total = input_total(&u_dft, n, scale);
    let kept_bins = match keep {
        Keep::All => None,
        Keep::UpTo { hz, extra_bins } => Some(kept_bins(
            u_dft.len(),
            n,
            sample_rate_hz,
            (hz, extra_bins),
            lpm,
        )),
    };
    // The command's transform becomes each output's H in place: the last
    // output takes it, the others a copy of what they read of it (all of
    // it for the LPM, which works on the whole transforms; else the kept
    // bins, as a fresh copy of the whole touches pages it then drops).
    let read = match (lpm, kept_bins) {
        (false, Some(bins)) => bins.min(u_dft.len()),
        _ => u_dft.len(),
    };
    let last = outputs.len().saturating_sub(1);
    let finish = Finish {
        n,
        scale,
        sample_rate_hz,
        coarse_resolution_hz: sample_rate_hz / coherence_segment_length as f64,
        lpm,
        kept_bins,
        keep,
    };
    let share = share && w.is_none() && detrend_kind == Detrend::Mean;
    let mut estimates = Vec::with_capacity(outputs.len());
    for (i, ((o, suy), coarse)) in outputs.iter().zip(y_dfts).zip(coarse).enumerate() {
        let h = if i == last && !share {
            std::mem::take(&mut u_dft)
        } else {
            u_dft[..read].to_vec()
        };
        estimates.push(Estimate {
            frf: finish.estimate(h, suy, &coarse, o.plan.transient()),
            input_total,
        });
    }
    Ok((estimates, share.then_some(u_dft)))
}

/// The input's density summed over every bin of its whole transform `u`
/// (of `n` samples) but DC: each bin's Suu as `etfe_from_transforms`
/// forms it with `scale`, in bin order.
fn input_total(u: &[Complex<f64>], n: usize, scale: f64) -> f64 {
    (1..u.len())
        .map(|k| {
            let s = scale * one_sided_factor(k, n);
            s * u[k].norm_sqr()
        })
        .sum()
}

/// How many of a transform's `nb` bins an estimate up to `f_hz` with
/// `extra` beyond keeps, by the frequencies `bin_frequencies` gives them,
/// and for the LPM the reach of its noise smoothing beyond.
fn kept_bins(
    nb: usize,
    n: usize,
    sample_rate_hz: f64,
    (f_hz, extra): (f64, usize),
    lpm: bool,
) -> usize {
    let resolution_hz = sample_rate_hz / n as f64;
    let below = (0..nb)
        .take_while(|&k| k as f64 * resolution_hz <= f_hz)
        .count();
    let reach = if lpm { lpm::SMOOTH_HALF_WIDTH } else { 0 };
    below.saturating_add(extra).saturating_add(reach)
}

/// What makes one output's whole-record estimate from its transforms, the
/// same for every output of one command.
struct Finish {
    n: usize,
    scale: f64,
    sample_rate_hz: f64,
    coarse_resolution_hz: f64,
    lpm: bool,
    kept_bins: Option<usize>,
    keep: Keep,
}

impl Finish {
    /// The estimate from the command's transform `h` and the output's
    /// `suy` (each whole, or the command's cut to the kept bins), the
    /// output's Welch `coarse` spectra for the coherence and the top of
    /// its `transient`, up to which the command's transform is kept.
    fn estimate(
        &self,
        mut h: Vec<Complex<f64>>,
        mut suy: Vec<Complex<f64>>,
        coarse: &Spectra,
        transient: Option<f64>,
    ) -> Frf {
        let (n, sample_rate_hz) = (self.n, self.sample_rate_hz);
        // The LPM works on the transforms themselves: kept before they
        // become H and Suy in place.
        let transforms = self.lpm.then(|| (h.clone(), suy.clone()));
        if let Some(bins) = self.kept_bins {
            for v in [&mut h, &mut suy] {
                v.truncate(bins);
                v.shrink_to_fit();
            }
        }
        // Up to the band's top only: a copy of a 14 M-sample record's whole
        // transform was 115 MB.
        let input_dft = transient.map(|f_hz| {
            let bins =
                ((f_hz * n as f64 / sample_rate_hz).floor() as usize + 1 + VARIANCE_REACH_BINS)
                    .min(h.len());
            h[..bins].to_vec()
        });
        let coarse_coherence = coherence_of(&coarse.suu, &coarse.syy, &coarse.suy);
        let mut frf = etfe_from_transforms(
            h,
            suy,
            n,
            self.scale,
            sample_rate_hz,
            &coarse_coherence,
            self.coarse_resolution_hz,
        );
        frf.input_dft = input_dft;
        let mut frf = match transforms {
            Some((u_k, y_k)) => lpm::take_out_transient(frf, &u_k, &y_k),
            None => frf,
        };
        if let Keep::UpTo { hz, extra_bins } = self.keep {
            frf.keep_up_to(hz, extra_bins);
        }
        frf
    }
}

/// The ETFE from the whole-record transforms U (in `h`) and Y (in `suy`),
/// on their bins (all n/2 + 1, or the first few: each bin is computed from
/// its own transforms alone): `scale` is 1/(fs sum w^2), and the coherence
/// is the Welch estimate `coarse_coherence` (on bins `coarse_resolution_hz`
/// apart) interpolated onto the ETFE's bins.
fn etfe_from_transforms(
    mut h: Vec<Complex<f64>>,
    mut suy: Vec<Complex<f64>>,
    n: usize,
    scale: f64,
    sample_rate_hz: f64,
    coarse_coherence: &[f64],
    coarse_resolution_hz: f64,
) -> Frf {
    // Per bin, in place: the transforms U and Y become H = Y/U and
    // Suy = conj(U) Y; Suu and Syy are new. Each bin is computed on its own,
    // so splitting the bins across threads changes no bit of the result.
    let nb = h.len();
    let mut suu = vec![0.0; nb];
    let mut syy = vec![0.0; nb];
    h.par_iter_mut()
        .zip(&mut suy)
        .zip(&mut suu)
        .zip(&mut syy)
        .enumerate()
        .with_min_len(PAR_MIN_BINS)
        .for_each(|(k, (((h_k, suy_k), suu_k), syy_k))| {
            let (uk, yk) = (*h_k, *suy_k);
            let s = scale * one_sided_factor(k, n);
            *suu_k = s * uk.norm_sqr();
            *syy_k = s * yk.norm_sqr();
            *suy_k = uk.conj() * yk * s;
            *h_k = ratio(yk, uk);
        });

    let resolution_hz = sample_rate_hz / n as f64;
    let freq_hz = bin_frequencies(nb, resolution_hz);
    let coherence = freq_hz
        .par_iter()
        .with_min_len(PAR_MIN_BINS)
        .map(|&f| interpolate(coarse_coherence, f / coarse_resolution_hz))
        .collect();
    Frf {
        freq_hz,
        h,
        coherence,
        suu,
        syy,
        suy,
        n_averages: 1,
        effective_averages: 1.0,
        method: Method::Etfe,
        resolution_hz,
        variance: None,
        input_dft: None,
        local_fits: LocalFits::default(),
    }
}

/// Periodic (DFT-even) window of length `n`: the symmetric window of length
/// n + 1 without its last sample, so that w(0) = 0 and w(n/2) = 1 for Hann
/// (Harris, Proc. IEEE 66(1), 1978, Sec. II). Length 1 gives `[1.0]`.
pub fn window(kind: Window, n: usize) -> Vec<f64> {
    if n == 1 {
        return vec![1.0];
    }
    // Generalised cosine windows sum_k (-1)^k a_k cos(2 pi k i / n).
    let coefficients: &[f64] = match kind {
        Window::Rectangular => return vec![1.0; n],
        Window::Hann => &[0.5, 0.5],
        Window::Hamming => &[0.54, 0.46],
        // Four-term, -92 dB side lobes (Harris 1978, Table I).
        Window::BlackmanHarris => &[0.35875, 0.48829, 0.14128, 0.01168],
    };
    (0..n)
        .map(|i| {
            let x = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            coefficients
                .iter()
                .enumerate()
                .map(|(k, a)| {
                    let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                    sign * a * (k as f64 * x).cos()
                })
                .sum()
        })
        .collect()
}

/// `x` with its mean (`Mean`) or least-squares straight line (`Linear`)
/// removed.
pub fn detrend(x: &[f64], kind: Detrend) -> Vec<f64> {
    let mut out = x.to_vec();
    detrend_in_place(&mut out, kind);
    out
}

/// The highest frequency (Hz) a run's FRFs keep beyond its band: the
/// paper's figures show up to 35 Hz (Figs. 7-9, 16-17), and the results'
/// tables and figures show what the analysis kept, never more.
pub const KEPT_MAX_HZ: f64 = 35.0;

/// Bins [`h_variance_at`] reads beyond the last bin it is asked for: the
/// moving average's S and the local polynomial's R (ETFE), plus one.
pub const VARIANCE_REACH_BINS: usize = ETFE_NOISE_SMOOTH_HALF_WIDTH + ETFE_LOCAL_HALF_WIDTH + 1;

impl Frf {
    /// The bins at positive frequencies up to `f_max_hz`: their
    /// frequencies, estimates and coherences, in order (what a figure shows
    /// of the estimate, and the control-structure interaction reads).
    pub fn positive_up_to(&self, f_max_hz: f64) -> (Vec<f64>, Vec<Complex<f64>>, Vec<f64>) {
        let mut out = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..self.freq_hz.len() {
            if self.freq_hz[i] > 0.0 && self.freq_hz[i] <= f_max_hz {
                out.0.push(self.freq_hz[i]);
                out.1.push(self.h[i]);
                out.2.push(self.coherence[i]);
            }
        }
        out
    }

    /// Drop the bins above `f_hz` but `extra` (see [`VARIANCE_REACH_BINS`]),
    /// and free their memory. An ETFE of a long record has a bin per
    /// 1/duration Hz up to Nyquist (7 M bins, 64 bytes each, for 7,000 s at
    /// 2,048 Hz) while an analysis reads a few per cent of them; what it
    /// reads, up to `f_hz` with `extra` bins of reach, is unchanged to the
    /// bit.
    pub fn keep_up_to(&mut self, f_hz: f64, extra: usize) {
        let keep = self.kept(f_hz, extra);
        fn cut<T>(v: &mut Vec<T>, keep: usize) {
            v.truncate(keep);
            v.shrink_to_fit();
        }
        cut(&mut self.freq_hz, keep);
        cut(&mut self.h, keep);
        cut(&mut self.coherence, keep);
        cut(&mut self.suu, keep);
        cut(&mut self.syy, keep);
        cut(&mut self.suy, keep);
        if let Some(v) = &mut self.variance {
            cut(v, keep);
        }
        if let Some(u) = &mut self.input_dft {
            cut(u, keep);
        }
    }

    /// The bins [`Frf::keep_up_to`] keeps.
    fn kept(&self, f_hz: f64, extra: usize) -> usize {
        self.freq_hz
            .partition_point(|f| *f <= f_hz)
            .saturating_add(extra)
            .min(self.freq_hz.len())
    }

    /// A copy of the bins [`Frf::keep_up_to`] would keep, without copying
    /// the rest first.
    pub fn head(&self, f_hz: f64, extra: usize) -> Frf {
        let keep = self.kept(f_hz, extra);
        Frf {
            freq_hz: self.freq_hz[..keep].to_vec(),
            h: self.h[..keep].to_vec(),
            coherence: self.coherence[..keep].to_vec(),
            suu: self.suu[..keep].to_vec(),
            syy: self.syy[..keep].to_vec(),
            suy: self.suy[..keep].to_vec(),
            n_averages: self.n_averages,
            effective_averages: self.effective_averages,
            method: self.method,
            resolution_hz: self.resolution_hz,
            variance: self
                .variance
                .as_ref()
                .map(|v| v[..keep.min(v.len())].to_vec()),
            input_dft: self
                .input_dft
                .as_ref()
                .map(|u| u[..keep.min(u.len())].to_vec()),
            local_fits: self.local_fits.clone(),
        }
    }

    /// The FRF with a transient taken out of it: at each bin with the
    /// command's DFT U, H less `t_over_u(f, U)` (the transient over U, in
    /// H's units), and the cross- and output spectra with it. Unchanged
    /// without [`Frf::input_dft`].
    pub fn without_transient(&mut self, t_over_u: impl Fn(f64, Complex<f64>) -> Complex<f64>) {
        let Some(u) = &self.input_dft else {
            return;
        };
        for (k, &uk) in u.iter().enumerate().take(self.h.len()).skip(1) {
            if uk.norm_sqr() == 0.0 {
                continue;
            }
            let t = t_over_u(self.freq_hz[k], uk);
            self.h[k] -= t;
            // Suy = s conj(U) Y and Suu = s |U|^2, so Y less T changes Suy
            // by Suu T/U; Syy = |Suy|^2 / Suu for a single record.
            self.suy[k] -= t * self.suu[k];
            if self.suu[k] > 0.0 {
                self.syy[k] = self.suy[k].norm_sqr() / self.suu[k];
            }
        }
    }
}

/// The rest test reads a tenth of the band's slowest period at each end
/// (0.2 s for a band from 0.5 Hz), at least [`REST_MIN_SAMPLES`]: the state
/// that leaks into the band is the one at the record's very ends, and a lab's
/// rest before and after a test is a second or so, however long the test.
pub const REST_WINDOW_PERIODS: f64 = 0.1;
pub const REST_MIN_SAMPLES: usize = 16;

/// The samples each end's rest window holds for a band from `lowest_hz`,
/// sampled at `sample_rate_hz` ([`REST_WINDOW_PERIODS`]).
pub fn rest_window(sample_rate_hz: f64, lowest_hz: f64) -> usize {
    let w = (REST_WINDOW_PERIODS * sample_rate_hz / lowest_hz).round();
    if w.is_finite() {
        (w as usize).max(REST_MIN_SAMPLES)
    } else {
        REST_MIN_SAMPLES
    }
}
/// An end whose signal moves by more than this share of the record's RMS
/// across its window, or that rests this far from the other end's level,
/// is not at rest.
pub const REST_RMS_RATIO: f64 = 0.1;

/// Where a signal is not at rest at the record's ends: "start", "end" or
/// "start and end" for an end whose window of `w` samples ([`rest_window`])
/// spans more than [`REST_RMS_RATIO`] of the record's RMS from its
/// lowest to its highest sample (it moves), or "end, away from its start"
/// for ends resting at levels that far apart; with the largest of those
/// ratios. None when both ends rest at one level. What matters is the
/// state's difference between the ends: the ETFE's DFT then holds its
/// leakage T(k) beside G U (see `fit::transient`); ends that rest at one
/// level, however far from the record's mean, leave none.
pub fn ends_in_motion(u: &[f64], w: usize) -> Option<(&'static str, f64)> {
    let n = u.len();
    if n < 4 * w {
        return None;
    }
    let mean = u.iter().sum::<f64>() / n as f64;
    let whole = (u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    if !(whole > 0.0 && whole.is_finite()) {
        return None;
    }
    let span = |x: &[f64]| {
        let (lo, hi) = x
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        (hi - lo) / whole
    };
    let level = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    let (first, last) = (&u[..w], &u[n - w..]);
    let (start, end) = (span(first), span(last));
    let apart = (level(last) - level(first)).abs() / whole;
    match (start > REST_RMS_RATIO, end > REST_RMS_RATIO) {
        (true, true) => Some(("start and end", start.max(end))),
        (true, false) => Some(("start", start)),
        (false, true) => Some(("end", end)),
        (false, false) if apart > REST_RMS_RATIO => Some(("end, away from its start", apart)),
        (false, false) => None,
    }
}

/// Noise multiples beyond which an end's window moves (its range) or the
/// ends rest at different levels (their means' difference, against the
/// means' own noise), for [`ends_against_noise`]: Gaussian noise over a
/// window of a few hundred samples spans about 7 times its std.
pub const REST_NOISE_RANGE: f64 = 15.0;
pub const REST_NOISE_LEVEL: f64 = 5.0;

/// [`ends_in_motion`], and also where the ends differ by more than the
/// signal's own noise would make them: an end window whose range exceeds
/// [`REST_NOISE_RANGE`] times the noise, or end levels further apart than
/// [`REST_NOISE_LEVEL`] times their difference's noise. The noise is read
/// from the end windows' sample-to-sample differences (their median
/// absolute deviation about the median difference, so that a steady slope
/// does not count), at least 1e-9 of the signal's RMS. Returns which end
/// and by how many times the noise. A drift of 0.4 um/s over 170 s leaves
/// the ends 68 um apart, 2.4 % of a sweep's RMS but 30 times the level's
/// noise under 2 um of LVDT noise: enough leakage in the band's lowest bins
/// to count tens of times the noise there.
pub fn ends_against_noise(x: &[f64], w: usize) -> Option<(&'static str, f64)> {
    let n = x.len();
    if n < 4 * w {
        return None;
    }
    let (sigma, rms) = noise_std(x, w);
    if let Some((end, ratio)) = ends_in_motion(x, w) {
        return Some((end, ratio * rms / sigma));
    }
    let (first, last) = (&x[..w], &x[n - w..]);
    let range = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &a| {
                (lo.min(a), hi.max(a))
            });
        (hi - lo) / sigma
    };
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (start, end) = (range(first), range(last));
    // The difference of two means of w samples has (2/w)^0.5 times the
    // noise.
    let apart = (mean(last) - mean(first)).abs() / (sigma * (2.0 / w as f64).sqrt());
    match (start > REST_NOISE_RANGE, end > REST_NOISE_RANGE) {
        (true, true) => Some(("start and end", start.max(end))),
        (true, false) => Some(("start", start)),
        (false, true) => Some(("end", end)),
        (false, false) if apart > REST_NOISE_LEVEL => Some(("end, away from its start", apart)),
        (false, false) => None,
    }
}

/// The noise std of `x` from its end windows of `w` samples (see
/// [`ends_against_noise`]), and its RMS.
fn noise_std(x: &[f64], w: usize) -> (f64, f64) {
    let n = x.len();
    let mean = x.iter().sum::<f64>() / n as f64;
    let rms = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let mut d: Vec<f64> = x[..w]
        .windows(2)
        .chain(x[n - w..].windows(2))
        .map(|p| p[1] - p[0])
        .collect();
    let median = |v: &mut Vec<f64>| {
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    let centre = median(&mut d);
    let mut dev: Vec<f64> = d.iter().map(|v| (v - centre).abs()).collect();
    // MAD to a Gaussian's std (1.4826), and a difference's std to the
    // samples' (2^-0.5).
    let sigma = 1.4826 * median(&mut dev) / std::f64::consts::SQRT_2;
    (sigma.max(1e-9 * rms), rms)
}

/// The index of the bin at `f_hz` in the ascending grid `freq_hz`: the
/// same frequency within `rel_tol` of it, as two FRFs of the same record
/// length and rate share their bins. None where the grid has no such bin.
pub fn bin_at(freq_hz: &[f64], f_hz: f64, rel_tol: f64) -> Option<usize> {
    let j = freq_hz.partition_point(|&g| g < f_hz);
    [j.wrapping_sub(1), j].into_iter().find(|&j| {
        freq_hz
            .get(j)
            .is_some_and(|g| (g / f_hz - 1.0).abs() <= rel_tol)
    })
}

/// Bins to fit: inside `band_hz` (inclusive), coherence at least
/// `coherence_min`, a finite, non-zero estimate, and for a single record
/// (the ETFE) an input there: a bin whose |U|^2 is below
/// [`UNEXCITED_SHARE`] of the band's mean holds no excitation (between a
/// multisine's tones), however coherent the coarser Welch segments around
/// it are.
pub fn band_mask(frf: &Frf, band_hz: (f64, f64), coherence_min: f64) -> Vec<bool> {
    let in_band = |f: f64| f >= band_hz.0 && f <= band_hz.1;
    let floor = if frf.n_averages == 1 {
        let (sum, n) = frf
            .freq_hz
            .iter()
            .zip(&frf.suu)
            .filter(|(f, _)| in_band(**f))
            .fold((0.0, 0usize), |(s, n), (_, p)| (s + p, n + 1));
        UNEXCITED_SHARE * sum / n.max(1) as f64
    } else {
        0.0
    };
    frf.freq_hz
        .iter()
        .zip(&frf.coherence)
        .zip(&frf.h)
        .zip(&frf.suu)
        .map(|(((&f, &c), h), &p)| {
            in_band(f)
                && c >= coherence_min
                && c > 0.0
                && p >= floor
                && h.re.is_finite()
                && h.im.is_finite()
                && h.norm_sqr() > 0.0
        })
        .collect()
}

/// The share of the band's mean input power below which an ETFE bin holds
/// no excitation: an unexcited bin of a periodic multisine sits some 100
/// dB below its tones; a Gaussian signal's bin falls this low once in a
/// million.
pub const UNEXCITED_SHARE: f64 = 1e-6;

/// Random-error variance of each of Re(H) and Im(H) at each bin (the weight
/// of a residual stacked as [Re; Im] is its inverse); the variance of the
/// complex estimate, E|H_est - H|^2, is twice this. Same as
/// [`h_variance_at`] over every bin.
pub fn h_variance(frf: &Frf) -> Vec<f64> {
    let all: Vec<usize> = (0..frf.h.len()).collect();
    h_variance_at(frf, &all)
}

/// Half-width (bins) of the ETFE's local polynomial window: 2 R + 1 = 15
/// bins, 12 complex degrees of freedom after the quadratic.
pub const ETFE_LOCAL_HALF_WIDTH: usize = 7;

/// Degree of the ETFE's local polynomial in the bin offset.
const ETFE_LOCAL_DEGREE: usize = 2;

/// Half-width (bins) of the moving average over the local noise densities:
/// one window's estimate has only 12 complex degrees of freedom, and
/// weights 1/sigma^2 drawn from so few make the fit's covariance about 10 %
/// optimistic in std (measured: 92 % of 1800 coefficients within 2 std over
/// 200 seeds). Averaging 2 S + 1 = 121 overlapping windows, less the 15
/// that hold the bin itself, leaves the weights' scatter negligible and
/// keeps a bin's own noise out of its weight (with S = 20 and the own
/// windows in, the joint stds were some 4 % optimistic). The noise level
/// is assumed smooth over the 121 bins (0.7 Hz of a 170 s record), as
/// sensor noise is.
pub const ETFE_NOISE_SMOOTH_HALF_WIDTH: usize = 60;

/// [`h_variance`] at the given bins only (the fit asks for its band's).
///
/// **Welch H1 and H2.** Bendat & Piersol (*Random Data*, 4th ed., Ch. 9,
/// gain and phase errors of H estimates) give for n_d averages the
/// normalised errors eps(|H|) = sd(phase) = sqrt((1 - g^2) / (2 n_d g^2)),
/// g^2 the coherence; magnitude and phase errors are the radial and
/// tangential components, so each Cartesian component has variance
/// (1 - g^2) |H|^2 / (2 n_d g^2).
///
/// Two corrections make this honest when computed from the estimates
/// themselves. First, K overlapping windowed segments are worth fewer than K
/// independent averages; Welch (1967, the variance of the averaged
/// periodogram) gives the equivalent number, stored as
/// [`Frf::effective_averages`]:
///
/// ```text
/// n_eff  = K / (1 + 2 sum_{j=1}^{K-1} (1 - j/K) rho(j)^2)
/// rho(j) = sum_i w(i) w(i + j S) / sum_i w(i)^2      (S the hop)
/// ```
///
/// (rho(1) = 1/6 for Hann at 50 % overlap, so n_eff ~ 0.95 K; the same
/// factor applies to the cross-spectrum of u with the noise, hence to H1).
/// Second, n_d = n_eff - 1: with the estimated coherence,
/// (1 - g^2) |H|^2 / g^2 = S_res / Suu, the residual spectrum over Suu, and
/// the residual's expectation is (1 - 1/n) times the noise spectrum (one
/// complex parameter fitted per bin), so dividing by n - 1 makes the
/// variance unbiased, as for a sample variance. The Monte Carlo test checks
/// the result to a few per cent. For H2 the same first-order expression
/// holds (H2 is H1 of the inverse path; delta method).
///
/// These assume stationary signals. For a sweep each frequency lives in one
/// or two segments, the coherence is biased towards 1 and the variance is
/// too small; the fit's reduced chi-square then exceeds 1 (and scales the
/// covariance), but the relative weights of the bins are not to be trusted.
///
/// **ETFE.** With a rectangular window over a record that starts and ends
/// at rest (a sweep with quiet lead-in and lead-out), Y(k) = G(k) U(k) +
/// V(k) holds exactly, the noise DFT bins V(k) are uncorrelated, and the
/// ETFE's error at bin k is V(k)/U(k), of variance sigma_V^2(k) / |U(k)|^2.
/// The noise level sigma_V^2(k) is estimated by the local polynomial method
/// (Pintelon, Schoukens et al., MSSP 24(3), 2010, 573-595; Pintelon &
/// Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed.,
/// 2012, Ch. 7) without its transient term: over the 2R + 1 bins around k
/// (R = [`ETFE_LOCAL_HALF_WIDTH`]), G is a quadratic in the bin offset r,
/// fitted to H by least squares weighted by Suu (the whitening weight,
/// since Suu(k) H(k) residuals = U(k)* V(k) scaled); the weighted residual
/// sum over its 2R + 1 - 3 complex degrees of freedom estimates the noise
/// density, which is averaged over the 2S + 1 bins around k (S =
/// [`ETFE_NOISE_SMOOTH_HALF_WIDTH`]) less those whose windows hold k,
/// and dividing it by Suu(k) gives the
/// bin's variance. G is smooth
/// over 2R + 1 bins of a long record, so what the polynomial leaves is
/// noise; leakage from a record that does not end at rest is counted as
/// noise too, which errs on the side of larger variances.
///
/// Infinite where there is no information (zero coherence or a single
/// Welch segment; an unexcited ETFE bin or a window without enough excited
/// bins); zero where the coherence is 1.
pub fn h_variance_at(frf: &Frf, bins: &[usize]) -> Vec<f64> {
    if frf.method == Method::Etfe {
        return etfe_variance(frf, bins);
    }
    if let Some(v) = &frf.variance {
        return bins
            .iter()
            .map(|&k| v.get(k).copied().unwrap_or(f64::INFINITY))
            .collect();
    }
    let dof = frf.effective_averages - 1.0;
    bins.iter()
        .map(|&k| {
            let (h, g2) = (frf.h[k], frf.coherence[k]);
            if g2 <= 0.0 || dof <= 0.0 {
                f64::INFINITY
            } else {
                (1.0 - g2) * h.norm_sqr() / (2.0 * dof * g2)
            }
        })
        .collect()
}

/// The ETFE's per-component variance at `bins`: the local noise densities
/// over the bins' span (widened by S on each side), averaged over 2 S + 1
/// bins, divided by Suu(k) and halved per component.
fn etfe_variance(frf: &Frf, bins: &[usize]) -> Vec<f64> {
    let nb = frf.h.len();
    let s_half = ETFE_NOISE_SMOOTH_HALF_WIDTH;
    let (Some(&lo), Some(&hi)) = (bins.iter().min(), bins.iter().max()) else {
        return Vec::new();
    };
    let span = lo.saturating_sub(s_half)..(hi + s_half + 1).min(nb);
    let density = etfe_local_noise_densities(frf, span.clone());
    // Prefix sums of the finite densities and of their count over the span.
    let mut sum = vec![0.0; span.len() + 1];
    let mut count = vec![0usize; span.len() + 1];
    for (i, &d) in density.iter().enumerate() {
        let finite = d.is_finite();
        sum[i + 1] = sum[i] + if finite { d } else { 0.0 };
        count[i + 1] = count[i] + usize::from(finite);
    }
    bins.iter()
        .map(|&k| {
            if k == 0 || k >= nb || frf.suu[k] <= 0.0 {
                return f64::INFINITY;
            }
            let a = k.saturating_sub(s_half).max(span.start) - span.start;
            let b = (k + s_half + 1).min(span.end) - span.start;
            if !density[k - span.start].is_finite() {
                return f64::INFINITY;
            }
            // Less the windows that hold bin k: their residuals hold V(k),
            // so a bin with a large error would be weighted down by its own
            // noise (the stds came out some 4 % optimistic with them in).
            let (mut own_sum, mut own_n) = (0.0, 0usize);
            let holding = windows_holding(k, nb, ETFE_LOCAL_HALF_WIDTH);
            let lo = a.max(holding.start.max(span.start) - span.start);
            let hi = b.min(holding.end.max(span.start) - span.start);
            for &d in density.get(lo..hi).unwrap_or_default() {
                if d.is_finite() {
                    own_sum += d;
                    own_n += 1;
                }
            }
            let n = count[b] - count[a] - own_n;
            if n == 0 {
                return f64::INFINITY;
            }
            let density = (sum[b] - sum[a] - own_sum) / n as f64;
            // Complex variance density / Suu(k); half of it per component.
            0.5 * density / frf.suu[k]
        })
        .collect()
}

/// The 2 `half` + 1 bins around bin `k` of a spectrum of `nb` bins that
/// the local polynomial fits use (the ETFE's noise level, the LPM):
/// shifted, not shortened, at the ends of the spectrum, DC left out. None
/// when the spectrum has no more bins than the window.
fn local_window(k: usize, nb: usize, half: usize) -> Option<std::ops::Range<usize>> {
    let width = 2 * half + 1;
    (nb > width).then(|| {
        let first = k.saturating_sub(half).clamp(1, nb - width);
        first..first + width
    })
}

/// The bins j whose [`local_window`] holds bin `k` (1 <= k < nb): a
/// range, since a window's first bin never falls as j rises. A window
/// starts at j - `half` away from the ends, so j runs from k - `half` to
/// k + `half`; every window holds k when k is among the first 2 `half` + 1
/// bins or the last, where the windows stop shifting.
fn windows_holding(k: usize, nb: usize, half: usize) -> std::ops::Range<usize> {
    let width = 2 * half + 1;
    if nb <= width || k == 0 {
        return 0..0;
    }
    let lo = if k <= width { 0 } else { k - half };
    let hi = if k < nb - width { k + half + 1 } else { nb };
    lo..hi
}

/// Discrete Fourier transform X(k) = sum_n x(n) exp(-2 pi i k n / N) for all
/// N bins, by the definition: O(N^2), the reference the FFT is tested against.
pub fn naive_dft(x: &[f64]) -> Vec<Complex<f64>> {
    let n = x.len();
    (0..n)
        .map(|k| {
            x.iter()
                .enumerate()
                .map(|(i, &v)| {
                    // Reduce k*i modulo N first so the angle stays exact.
                    let m = (k as u128 * i as u128 % n as u128) as f64;
                    let angle = -2.0 * std::f64::consts::PI * m / n as f64;
                    Complex::new(v * angle.cos(), v * angle.sin())
                })
                .sum()
        })
        .collect()
}

fn check_inputs(
    u: &[f64],
    y: &[f64],
    sample_rate_hz: f64,
    segment_length: usize,
    overlap: f64,
) -> Result<(), FrfError> {
    if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0) {
        return Err(FrfError::BadSampleRate(sample_rate_hz));
    }
    if !(0.0..1.0).contains(&overlap) {
        return Err(FrfError::BadOverlap(overlap));
    }
    if segment_length < MIN_SEGMENT_LENGTH {
        return Err(FrfError::SegmentTooShort(segment_length));
    }
    if u.len() != y.len() {
        return Err(FrfError::LengthMismatch {
            u_len: u.len(),
            y_len: y.len(),
        });
    }
    if u.len() < segment_length {
        return Err(FrfError::TooShort {
            samples: u.len(),
            segment_length,
        });
    }
    for (signal, x) in [("u", u), ("y", y)] {
        // A branch-free pass over blocks (it vectorises); the search for the
        // first bad index runs only when something is wrong.
        let all_finite = x
            .chunks(1024)
            .all(|block| block.iter().fold(true, |ok, v| ok & v.is_finite()));
        if all_finite {
            continue;
        }
        if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(FrfError::NonFinite {
                signal,
                index,
                value,
            });
        }
    }
    Ok(())
}

/// Fewest bins per parallel task in the per-bin passes: below this, handing
/// work to another thread costs more than it saves.
const PAR_MIN_BINS: usize = 8192;

/// Fewest local polynomial fits (about 0.2 us each) per parallel task.
const PAR_MIN_LOCAL_FITS: usize = 512;

thread_local! {
    // The input and scratch buffers of the last transforms this thread ran,
    // kept for the next: a whole-record transform needs 16n bytes of them,
    // and touching that much fresh memory on every call cost as much as the
    // transform itself (page faults; about 3 us a page on a virtual
    // machine). The thread holds at most the largest record's worth, and
    // none of a record longer than SPARE_MAX_SAMPLES.
    static SPARE_BUFFERS: std::cell::RefCell<(Vec<f64>, Vec<Complex<f64>>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// The longest record whose transform's buffers a thread keeps: 2^21
/// samples (35 min at 1 kHz), 34 MB a thread. A longer record's 16 bytes a
/// sample stayed with the thread through the rest of its run: on a
/// 7,000 s log at 2,048 Hz, 0.23 GB held while its tracking took as much
/// again, beside the log's own signals. Its transforms' page faults are
/// small beside its analysis.
const SPARE_MAX_SAMPLES: usize = 1 << 21;

/// A planned real FFT of one length with its working buffers: built once per
/// call and reused for every segment, so the segment loop does not allocate.
/// The buffers come from the thread's spares and go back when it is dropped;
/// their contents never matter, as `run` overwrites the input and realfft
/// the scratch.
struct SegmentTransform {
    r2c: Arc<dyn RealToComplex<f64>>,
    buf: Vec<f64>,
    scratch: Vec<Complex<f64>>,
}

impl SegmentTransform {
    fn new(n: usize) -> Self {
        let r2c = crate::fft::real_forward(n);
        let (mut buf, mut scratch) = SPARE_BUFFERS.with(|s| std::mem::take(&mut *s.borrow_mut()));
        buf.resize(n, 0.0);
        scratch.resize(r2c.get_scratch_len(), Complex::new(0.0, 0.0));
        Self { r2c, buf, scratch }
    }

    /// A buffer for the n/2 + 1 bins of one transform.
    fn make_output(&self) -> Vec<Complex<f64>> {
        self.r2c.make_output_vec()
    }

    /// Detrends `x`, multiplies it by `w` (no window: rectangular) and writes
    /// its DFT (bins 0 ..= n/2) into `out`; `x`, `w` and `out` have the
    /// planned lengths.
    fn run(
        &mut self,
        x: &[f64],
        w: Option<&[f64]>,
        detrend_kind: Detrend,
        out: &mut [Complex<f64>],
    ) {
        // One pass: detrend and window straight from `x` into the buffer.
        let trend = Trend::of(x, detrend_kind);
        let buf = self.buf.iter_mut().zip(x);
        match (w, trend.slope == 0.0) {
            // Mean or none: the same values as `detrend`, without the ramp.
            (Some(w), true) => buf
                .zip(w)
                .for_each(|((b, &v), &w)| *b = (v - trend.offset) * w),
            (Some(w), false) => buf
                .zip(w)
                .enumerate()
                .for_each(|(i, ((b, &v), &w))| *b = (v - trend.at(i)) * w),
            (None, true) => buf.for_each(|(b, &v)| *b = v - trend.offset),
            (None, false) => buf
                .enumerate()
                .for_each(|(i, (b, &v))| *b = v - trend.at(i)),
        }
        // realfft checks only the lengths, which come from the plan.
        self.r2c
            .process_with_scratch(&mut self.buf, out, &mut self.scratch)
            .expect("buffer lengths come from the plan");
    }
}

impl Drop for SegmentTransform {
    fn drop(&mut self) {
        let buffers = (
            std::mem::take(&mut self.buf),
            std::mem::take(&mut self.scratch),
        );
        if buffers.0.capacity() > SPARE_MAX_SAMPLES {
            return;
        }
        // Not kept when the thread is being torn down.
        let _ = SPARE_BUFFERS.try_with(|s| {
            let mut spare = s.borrow_mut();
            // Keep the larger set when two transforms were alive at once.
            if buffers.0.capacity() >= spare.0.capacity() {
                *spare = buffers;
            }
        });
    }
}

/// Averaged one-sided densities of checked inputs.
struct Spectra {
    suu: Vec<f64>,
    syy: Vec<f64>,
    suy: Vec<Complex<f64>>,
    n_segments: usize,
    effective_averages: f64,
}

/// How a record is cut into Welch segments and each segment prepared.
struct Segmenting {
    length: usize,
    overlap: f64,
    window_kind: Window,
    detrend_kind: Detrend,
}

fn welch_spectra(u: &[f64], y: &[f64], sample_rate_hz: f64, segments: &Segmenting) -> Spectra {
    welch_spectra_many(u, &[y], sample_rate_hz, segments)
        .pop()
        .expect("one output's spectra")
}

/// [`welch_spectra`] of `u` with each of `ys`, each segment of `u`
/// transformed once for all of them; each output's sums are added in the
/// same order as alone, so their bits are the same.
fn welch_spectra_many(
    u: &[f64],
    ys: &[&[f64]],
    sample_rate_hz: f64,
    segments: &Segmenting,
) -> Vec<Spectra> {
    let Segmenting {
        length: l,
        overlap,
        window_kind,
        detrend_kind,
    } = *segments;
    // overlap < 1, so the hop is at least one sample.
    let hop = l - (overlap * l as f64).floor() as usize;
    let n_segments = (u.len() - l) / hop + 1;
    let w = window(window_kind, l);

    // One plan and one set of buffers for every segment.
    let mut transform = SegmentTransform::new(l);
    let mut uf = transform.make_output();
    let mut yf = transform.make_output();
    let nb = uf.len();
    let mut sums: Vec<_> = ys
        .iter()
        .map(|_| {
            (
                vec![0.0; nb],
                vec![0.0; nb],
                vec![Complex::new(0.0, 0.0); nb],
            )
        })
        .collect();

    for s in 0..n_segments {
        let segment = s * hop..s * hop + l;
        transform.run(&u[segment.clone()], Some(&w), detrend_kind, &mut uf);
        for (y, (suu, syy, suy)) in ys.iter().zip(&mut sums) {
            transform.run(&y[segment.clone()], Some(&w), detrend_kind, &mut yf);
            accumulate_segment(&uf, &yf, (suu, syy, suy));
        }
    }
    let effective_averages = effective_averages(&w, hop, n_segments);
    sums.into_iter()
        .map(|(mut suu, mut syy, mut suy)| {
            to_density(
                (&mut suu, &mut syy, &mut suy),
                sample_rate_hz,
                &w,
                n_segments,
            );
            Spectra {
                suu,
                syy,
                suy,
                n_segments,
                effective_averages,
            }
        })
        .collect()
}

/// Adds one segment's |U|^2, |Y|^2 and conj(U) Y to the running sums, bin
/// by bin (over the sums' bins: all of a segment's, or its first few).
fn accumulate_segment(
    uf: &[Complex<f64>],
    yf: &[Complex<f64>],
    (suu, syy, suy): (&mut [f64], &mut [f64], &mut [Complex<f64>]),
) {
    for k in 0..suu.len() {
        suu[k] += uf[k].norm_sqr();
        syy[k] += yf[k].norm_sqr();
        suy[k] += uf[k].conj() * yf[k];
    }
}

/// The sums of `n_segments` segments of length `w.len()` made one-sided
/// densities: |X|^2 / (fs sum w^2), averaged, doubled off DC and Nyquist,
/// so that sum(S df) is the mean square (Parseval).
fn to_density(
    (suu, syy, suy): (&mut [f64], &mut [f64], &mut [Complex<f64>]),
    sample_rate_hz: f64,
    w: &[f64],
    n_segments: usize,
) {
    let scale = 1.0 / (sample_rate_hz * w.iter().map(|v| v * v).sum::<f64>() * n_segments as f64);
    for k in 0..suu.len() {
        let s = scale * one_sided_factor(k, w.len());
        suu[k] *= s;
        syy[k] *= s;
        suy[k] *= s;
    }
}

/// Welch's (1967) equivalent number of independent averages of `k`
/// overlapping segments windowed by `w` and `hop` samples apart.
fn effective_averages(w: &[f64], hop: usize, k: usize) -> f64 {
    let mut sum = 0.0;
    for j in 1..k {
        let shift = j * hop;
        if shift >= w.len() {
            break;
        }
        let rho = overlap_correlation(w, shift);
        sum += (1.0 - j as f64 / k as f64) * rho * rho;
    }
    k as f64 / (1.0 + 2.0 * sum)
}

/// Correlation of a window with itself shifted by `shift` samples, normalised
/// by its energy (Harris 1978, "overlap correlation").
fn overlap_correlation(w: &[f64], shift: usize) -> f64 {
    let energy: f64 = w.iter().map(|v| v * v).sum();
    let cross: f64 = w.iter().zip(&w[shift..]).map(|(a, b)| a * b).sum();
    cross / energy
}

/// 2 for the bins that stand for a positive and a negative frequency, 1 for
/// DC and (even lengths) Nyquist.
fn one_sided_factor(k: usize, n: usize) -> f64 {
    if k == 0 || (n.is_multiple_of(2) && k == n / 2) {
        1.0
    } else {
        2.0
    }
}

fn coherence_of(suu: &[f64], syy: &[f64], suy: &[Complex<f64>]) -> Vec<f64> {
    suu.iter()
        .zip(syy)
        .zip(suy)
        .map(|((&a, &b), c)| {
            let denominator = a * b;
            if denominator > 0.0 {
                // Rounding can put a perfectly coherent bin a hair above 1.
                (c.norm_sqr() / denominator).clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
        .collect()
}

/// num / den, or 0 when den is exactly 0 (such a bin has zero coherence).
fn ratio(num: Complex<f64>, den: Complex<f64>) -> Complex<f64> {
    if den.norm_sqr() > 0.0 {
        num / den
    } else {
        Complex::new(0.0, 0.0)
    }
}

fn bin_frequencies(n_bins: usize, resolution_hz: f64) -> Vec<f64> {
    (0..n_bins)
        .into_par_iter()
        .with_min_len(PAR_MIN_BINS)
        .map(|k| k as f64 * resolution_hz)
        .collect()
}

/// Linear interpolation of `values` (on bins 0, 1, 2, ...) at fractional bin
/// `position`, clamped to the ends.
fn interpolate(values: &[f64], position: f64) -> f64 {
    let last = values.len() - 1;
    if position <= 0.0 {
        return values[0];
    }
    let i = position.floor() as usize;
    if i >= last {
        return values[last];
    }
    let t = position - i as f64;
    values[i] * (1.0 - t) + values[i + 1] * t
}

/// The trend `detrend` removes, as value(i) = offset + slope (i - centre)
/// with centre = (n - 1)/2: least squares on a centred abscissa, where the
/// mean and the slope decouple (slope = sum t x / sum t^2, with
/// sum t^2 = n (n^2 - 1)/12).
#[derive(Debug, Clone, Copy)]
struct Trend {
    offset: f64,
    slope: f64,
    centre: f64,
}

impl Trend {
    fn of(x: &[f64], kind: Detrend) -> Self {
        let n = x.len();
        let centre = (n as f64 - 1.0) / 2.0;
        let none = Self {
            offset: 0.0,
            slope: 0.0,
            centre,
        };
        if n == 0 || kind == Detrend::None {
            return none;
        }
        let offset = lane_sum(x, |_, v| v) / n as f64;
        let slope = if kind == Detrend::Linear && n > 1 {
            let stt = n as f64 * (n as f64 * n as f64 - 1.0) / 12.0;
            lane_sum(x, |i, v| (i as f64 - centre) * v) / stt
        } else {
            0.0
        };
        Self {
            offset,
            slope,
            centre,
        }
    }

    fn at(&self, i: usize) -> f64 {
        self.offset + self.slope * (i as f64 - self.centre)
    }
}

fn detrend_in_place(x: &mut [f64], kind: Detrend) {
    let trend = Trend::of(x, kind);
    for (i, v) in x.iter_mut().enumerate() {
        *v -= trend.at(i);
    }
}

/// sum_i f(i, x(i)) in eight interleaved partial sums added in a fixed order:
/// the compiler can vectorise it (a single running sum is a serial chain),
/// the rounding is no worse, and the result depends only on the input.
fn lane_sum(x: &[f64], f: impl Fn(usize, f64) -> f64) -> f64 {
    const LANES: usize = 8;
    let mut acc = [0.0; LANES];
    let chunks = x.chunks_exact(LANES);
    let tail = chunks.remainder();
    for (c, chunk) in chunks.enumerate() {
        for (lane, (a, &v)) in acc.iter_mut().zip(chunk).enumerate() {
            *a += f(c * LANES + lane, v);
        }
    }
    let start = x.len() - tail.len();
    let tail_sum: f64 = tail.iter().enumerate().map(|(j, &v)| f(start + j, v)).sum();
    let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
    ((a0 + a4) + (a2 + a6)) + ((a1 + a5) + (a3 + a7)) + tail_sum
}

#[cfg(test)]
mod tests;
