//! A warning as a lab reads it: a headline to take in at a glance (the
//! cause and the number that shows it), and its detail (the evidence, the
//! remedy, the keys) where the lab looks closer: the run's page,
//! results.json and `--verbose`. The campaign page's tables and the
//! command line show headlines, so a night of hundreds of runs stays one
//! line a run.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The longest headline, in characters.
pub const HEADLINE_MAX: usize = 100;

/// What did not stop a run or a campaign but a lab should know.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub struct Warning {
    /// The cause and the number that shows it, at most 100 characters.
    pub headline: String,
    /// The whole statement: the evidence, the remedy and the keys.
    pub detail: String,
}

impl Warning {
    pub fn new(headline: impl Into<String>, detail: impl Into<String>) -> Self {
        Self {
            headline: headline.into(),
            detail: detail.into(),
        }
    }

    /// Whether the headline or the detail holds `text`.
    pub fn contains(&self, text: &str) -> bool {
        self.headline.contains(text) || self.detail.contains(text)
    }

    /// The same warning with its headline and detail prefixed (a run's id,
    /// the rig's stage).
    pub fn prefixed(self, prefix: &str) -> Self {
        Self {
            headline: format!("{prefix}{}", self.headline),
            detail: format!("{prefix}{}", self.detail),
        }
    }
}

impl std::fmt::Display for Warning {
    /// The headline; `{:#}` adds the detail on the next line.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if f.alternate() {
            write!(f, "{}\n  {}", self.headline, self.detail)
        } else {
            f.write_str(&self.headline)
        }
    }
}
