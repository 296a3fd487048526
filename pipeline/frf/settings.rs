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

/// Trend removed from each segment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Detrend {
    None,
    #[default]
    Mean,
    Linear,
}
