//! The fit stage's settings that the manifest chooses: how the command
//! reaches the plant between samples, and how a pure delay enters the model.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Intersample behaviour of the logged command.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Intersample {
    /// Played through a D/A converter that holds each sample.
    #[default]
    SampleAndHold,
    /// No hold modelled.
    None,
}

/// How a pure delay enters the fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DelayPlan {
    None,
    Fixed { delay_s: f64 },
    Fit { max_s: f64 },
}
