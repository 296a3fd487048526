//! The FRF stage's settings: the estimator, Welch's segments, window and
//! detrending. The manifest reads them (its `identification.frf` table uses
//! these types) and checks them into an [`FrfPlan`].

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Checked FRF settings.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfPlan {
    pub estimator: Estimator,
    pub segment_length: usize,
    pub overlap: f64,
    pub window: Window,
    pub detrend: Detrend,
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
    /// Welch H1 = Syu/Suu (noise on the output).
    #[default]
    H1,
    /// Welch H2 = Syy/Suy (noise on the input).
    H2,
    /// Empirical transfer-function estimate Y/U over the whole record.
    Etfe,
    /// The ETFE with the local polynomial method's transient term taken
    /// out of the estimate and of its variance (Pintelon, Schoukens,
    /// Vandersteen & Barbe 2010, MSSP 24(3), 573-595): for records that do
    /// not start and end at rest, or whose sensor drifts.
    Lpm,
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
