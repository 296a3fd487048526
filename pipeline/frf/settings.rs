//! The FRF stage's settings: the estimator, Welch's segments, window and
//! detrending. The manifest reads them (its `identification.frf` table uses
//! these types) and checks them into an [`FrfRequest`](super::FrfRequest),
//! which each run's log resolves into an [`FrfPlan`] of a [`Method`].

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{FrfError, MIN_SEGMENT_LENGTH};

/// The FRF settings of one run, every one decided: a resolved [`Method`],
/// Welch's segments (the coherence's, for a whole-record method), the
/// window, the detrending, and how the run's fit reads the record. Built by
/// [`FrfPlan::new`], which refuses segments no estimate could use, so a
/// plan in hand is one the estimators accept.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "PlanFields")]
pub struct FrfPlan {
    // Serialised under the manifest's name (a run cache's entries).
    #[serde(rename = "estimator")]
    method: Method,
    segment_length: usize,
    overlap: f64,
    window: Window,
    detrend: Detrend,
    transient: Option<f64>,
    model_noise: bool,
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    steady_periods: bool,
}

/// What a serialised [`FrfPlan`] holds, checked by [`FrfPlan::new`] on the
/// way in.
#[derive(Deserialize)]
struct PlanFields {
    estimator: Method,
    segment_length: usize,
    overlap: f64,
    window: Window,
    detrend: Detrend,
    transient: Option<f64>,
    model_noise: bool,
    #[serde(default)]
    steady_periods: bool,
}

impl TryFrom<PlanFields> for FrfPlan {
    type Error = FrfError;

    fn try_from(f: PlanFields) -> Result<Self, FrfError> {
        let plan = FrfPlan::new(
            f.estimator,
            f.segment_length,
            f.overlap,
            f.window,
            f.detrend,
        )?
        .with_model_noise(f.model_noise)
        .with_steady_periods(f.steady_periods);
        Ok(match f.transient {
            Some(top_hz) => plan.with_transient(top_hz),
            None => plan,
        })
    }
}

impl FrfPlan {
    /// A plan of `method` with Welch segments of `segment_length` samples
    /// overlapping by `overlap` (for the ETFE and the LPM, the segments of
    /// their coherence), each detrended and windowed; no transient fitted
    /// and the noise read from the FRF. Refused for segments shorter than
    /// [`MIN_SEGMENT_LENGTH`] or an overlap outside [0, 1), as the manifest
    /// refuses them.
    pub fn new(
        method: Method,
        segment_length: usize,
        overlap: f64,
        window: Window,
        detrend: Detrend,
    ) -> Result<Self, FrfError> {
        if !(0.0..1.0).contains(&overlap) {
            return Err(FrfError::BadOverlap(overlap));
        }
        if segment_length < MIN_SEGMENT_LENGTH {
            return Err(FrfError::SegmentTooShort(segment_length));
        }
        Ok(Self {
            method,
            segment_length,
            overlap,
            window,
            detrend,
            transient: None,
            model_noise: false,
            steady_periods: false,
        })
    }

    /// The plan with the record's transient fitted beside the run's model
    /// (`fit::transient`), as `auto` fits it where the record does not
    /// rest at its ends: a whole-record estimate then keeps the command's
    /// DFT ([`Frf::input_dft`](super::Frf::input_dft)) up to `top_hz`
    /// (the band's top) and the noise estimate's reach beyond, where the
    /// transient is fitted and taken out.
    pub fn with_transient(self, top_hz: f64) -> Self {
        Self {
            transient: Some(top_hz),
            ..self
        }
    }

    /// The plan with no transient fitted.
    pub fn without_transient(self) -> Self {
        Self {
            transient: None,
            ..self
        }
    }

    /// The plan with the run's fit reading its bins' noise level from what
    /// a first fit leaves (`identify::fit_run`) rather than from the FRF
    /// itself, as `auto` does: the ETFE's local polynomials then follow
    /// only the model's smooth misfit, not the plant's own curvature,
    /// which over the wide bins of a short record they cannot (the noise
    /// came out 14 % high on 20 s records, 38 % on 10 s ones).
    pub fn with_model_noise(self, model_noise: bool) -> Self {
        Self {
            model_noise,
            ..self
        }
    }

    /// The plan for a record of whole steady periods of a periodic
    /// command (`frf::periodic`) or not: the fit then reads its excited
    /// lines with no transient between them (`frf::at_lines`).
    pub fn with_steady_periods(self, steady_periods: bool) -> Self {
        Self {
            steady_periods,
            ..self
        }
    }

    /// Whether the record is whole steady periods
    /// ([`FrfPlan::with_steady_periods`]).
    pub fn steady_periods(&self) -> bool {
        self.steady_periods
    }

    pub fn method(&self) -> Method {
        self.method
    }

    /// Samples in a Welch segment (for a whole-record method, in a segment
    /// of its coherence).
    pub fn segment_length(&self) -> usize {
        self.segment_length
    }

    /// The share of a segment the next one overlaps, in [0, 1).
    pub fn overlap(&self) -> f64 {
        self.overlap
    }

    pub fn window(&self) -> Window {
        self.window
    }

    pub fn detrend(&self) -> Detrend {
        self.detrend
    }

    /// The band's top (Hz) up to which the record's transient is fitted,
    /// when it is ([`FrfPlan::with_transient`]).
    pub fn transient(&self) -> Option<f64> {
        self.transient
    }

    /// Whether the run's fit reads the noise level from a first fit's
    /// misfit ([`FrfPlan::with_model_noise`]).
    pub fn model_noise(&self) -> bool {
        self.model_noise
    }

    /// Whether two plans make the same estimate of a command's transforms,
    /// differing at most in the transient (which decides only whether the
    /// command's transform is kept) and in how the fit reads the noise.
    pub(super) fn same_but_transient(&self, other: &FrfPlan) -> bool {
        let bare = |p: &FrfPlan| p.clone().without_transient().with_model_noise(false);
        bare(self) == bare(other)
    }

    /// The lag in bins beyond which the estimate's noise is uncorrelated
    /// between bins: the window's kernel ([`Window::independent_lag`]), or
    /// for the LPM its local window, 2R + 1 = 15 bins (neighbouring bins
    /// share the transient's estimates: their errors correlate at r = +0.06
    /// to +0.09 one bin apart on the records of `tests/joint.rs`).
    pub fn independent_lag(&self) -> usize {
        match self.method {
            Method::Lpm => 2 * super::lpm::HALF_WIDTH + 1,
            _ => self.window.independent_lag(),
        }
    }
}

/// An FRF estimator as a plan and an estimate hold it: one of the
/// manifest's [`Estimator`]s but `Auto`, which each run's log resolves
/// (`FrfRequest::resolve`). Serialised as the manifest names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Welch H1 = Suy/Suu (noise on the output), averaged over segments
    /// (P. D. Welch, IEEE Trans. Audio Electroacoust. 15(2), 1967, 70-73):
    /// segments of the plan's length starting every
    /// `segment_length - floor(overlap * segment_length)` samples (samples
    /// after the last whole segment are not used), each detrended, then
    /// windowed, then transformed; spectra averaged in segment order.
    H1,
    /// Welch H2 = Syy/Syu, Syu = conj(Suy) (noise on the input), over the
    /// segments of [`Method::H1`].
    H2,
    /// Empirical transfer-function estimate Y/U (Ljung, *System
    /// Identification*, 2nd ed., Sec. 6.3): one window over the whole
    /// record, one transform, no averaging, so the resolution is fs /
    /// record length and `n_averages` is 1. A single average has coherence
    /// identically 1, which says nothing about noise; so the coherence is
    /// taken from a Welch estimate over the plan's segments, linearly
    /// interpolated onto the ETFE's bins, and masking works as for H1. The
    /// densities are the whole-record periodograms (scaled as Welch's), so
    /// `h = suy / suu`. For a sweep, prefer `Window::Rectangular`: a
    /// tapered window over the whole record suppresses the frequencies
    /// swept at its start and end.
    Etfe,
    /// The ETFE with the local polynomial method's transient taken out of
    /// the estimate and of its variance, from the whole-record transforms
    /// (which it needs with their phases).
    Lpm,
}

impl Method {
    /// Whether the estimate averages Welch segments (H1, H2) rather than
    /// transforming the whole record (the ETFE, the LPM).
    pub fn is_welch(self) -> bool {
        matches!(self, Method::H1 | Method::H2)
    }
}

impl From<Method> for Estimator {
    fn from(method: Method) -> Self {
        match method {
            Method::H1 => Estimator::H1,
            Method::H2 => Estimator::H2,
            Method::Etfe => Estimator::Etfe,
            Method::Lpm => Estimator::Lpm,
        }
    }
}

/// FRF estimator.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Chosen per run from its log and the band (`frf::choice`): the ETFE
    /// over the whole record with a rectangular window, the record's
    /// transient fitted beside the model where it does not start and end
    /// at rest, and the coherence's segments from the record's length and
    /// the band.
    #[default]
    Auto,
    /// Welch H1 = Suy/Suu, Suy = conj(U) Y (noise on the output).
    H1,
    /// Welch H2 = Syy/Syu, Syu = conj(Suy) (noise on the input).
    H2,
    /// Empirical transfer-function estimate Y/U over the whole record.
    Etfe,
    /// The ETFE with the local polynomial method's transient term taken
    /// out of the estimate and of its variance (Pintelon, Schoukens,
    /// Vandersteen & Barbe 2010, MSSP 24(3), 573-595): for records that do
    /// not start and end at rest, or whose sensor drifts.
    Lpm,
}

impl Estimator {
    /// The estimator a plan holds; None for `Auto`, which needs the log.
    pub fn resolved(self) -> Option<Method> {
        match self {
            Estimator::Auto => None,
            Estimator::H1 => Some(Method::H1),
            Estimator::H2 => Some(Method::H2),
            Estimator::Etfe => Some(Method::Etfe),
            Estimator::Lpm => Some(Method::Lpm),
        }
    }

    /// The likely cause, with its remedy, of a noise this estimator's
    /// variances understate (a fit's cost above its expectation with no
    /// structure in the residuals): what a fit's diagnosis says.
    pub fn understated_noise(self) -> &'static str {
        match self {
            // Welch's coherence-based variance is biased low where the
            // coherence is near 1 and the segments do not hold the same
            // spectrum (a sweep: each segment sees a different band).
            Estimator::H1 | Estimator::H2 => {
                "noise the variances understate (a sweep analysed with H1/H2, whose coherence is biased); leave identification.frf.estimator out (\"auto\") for a sweep"
            }
            // The ETFE's and the LPM's variances are local averages of the
            // residual spectrum: what they miss is distortion that is not
            // noise, or noise that changes faster than the average follows.
            Estimator::Auto | Estimator::Etfe | Estimator::Lpm => {
                "noise the variances understate (a nonlinearity's distortion, or noise that changes along the record or across a few bins); check the specimen and the rig for friction or a nonlinear spring"
            }
        }
    }

    /// The likely cause, with its remedy, of a noise this estimator's
    /// variances overstate (a fit's cost, or its neighbouring residuals'
    /// correlation, well below expectation).
    pub fn overstated_noise(self) -> &'static str {
        match self {
            Estimator::Lpm | Estimator::Auto => {
                "noise that changes along the record (the variance is the record's average), or a transient faster than the local polynomials follow"
            }
            _ => {
                "a transient or a drift the FRF estimator counts as noise (a record not at rest at its ends, a drifting sensor); the default estimator (\"auto\") takes them out"
            }
        }
    }
}

/// Window applied to each segment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Window {
    #[default]
    Hann,
    Hamming,
    BlackmanHarris,
    Rectangular,
}

impl Window {
    /// The lag in bins beyond which a segment's noise is uncorrelated
    /// between bins (the width of the window's spectral kernel): 1 for a
    /// rectangular window, 3 for Hann and Hamming (3-bin kernels), 7 for the
    /// 4-term Blackman-Harris (a 7-bin kernel). The fits' residual
    /// correlation test pairs bins this far apart.
    pub fn independent_lag(self) -> usize {
        match self {
            Window::Rectangular => 1,
            Window::Hann | Window::Hamming => 3,
            Window::BlackmanHarris => 7,
        }
    }
}

/// Trend removed from each segment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Detrend {
    None,
    #[default]
    Mean,
    Linear,
}
