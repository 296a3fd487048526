//! The FRF stage's settings: the estimator, Welch's segments, window and
//! detrending. The manifest reads them (its `identification.frf` table uses
//! these types) and checks them into an [`FrfRequest`](super::FrfRequest),
//! which each run's log resolves into an [`FrfPlan`].

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The FRF settings of one run, every one decided: the estimator is never
/// `Auto` here.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrfPlan {
    pub estimator: Estimator,
    pub segment_length: usize,
    pub overlap: f64,
    pub window: Window,
    pub detrend: Detrend,
    /// Some(f): the run's fit takes the record's transient out beside its
    /// model (`fit::transient`), as `auto` does; the ETFE keeps the
    /// command's DFT up to f Hz (the band's top) and the noise estimate's
    /// reach, where the transient is fitted and taken out.
    pub transient: Option<f64>,
    /// Whether the run's fit reads its bins' noise level from what a first
    /// fit leaves (`identify::fit_run`) rather than from the FRF
    /// itself, as `auto` does: the ETFE's local polynomials then follow
    /// only the model's smooth misfit, not the plant's own curvature,
    /// which over the wide bins of a short record they cannot (the noise
    /// came out 14 % high on 20 s records, 38 % on 10 s ones).
    pub model_noise: bool,
}

impl FrfPlan {
    /// The lag in bins beyond which the estimate's noise is uncorrelated
    /// between bins: the window's kernel ([`Window::independent_lag`]), or
    /// for the LPM its local window, 2R + 1 = 15 bins (neighbouring bins
    /// share the transient's estimates: their errors correlate at r = +0.06
    /// to +0.09 one bin apart on the records of `tests/joint.rs`).
    pub fn independent_lag(&self) -> usize {
        match self.estimator {
            Estimator::Lpm => 2 * super::lpm::HALF_WIDTH + 1,
            _ => self.window.independent_lag(),
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
