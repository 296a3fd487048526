//! A campaign's identification settings, checked: the stages' own
//! settings (the FRF's, the fit's, the delay's) as the manifest states them.

use crate::fit::{DelayPlan, Intersample};
use crate::frf::FrfRequest;

/// Checked identification options.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentificationPlan {
    pub band_hz: (f64, f64),
    pub coherence_min: f64,
    /// The FRF settings as stated; each run's log resolves them.
    pub frf: FrfRequest,
    pub intersample: Intersample,
    pub delay: DelayPlan,
    /// The longest delay a fit may find (s): `identification.delay.max_s`,
    /// whatever the mode, for the fits that look for a delay the
    /// manifest's mode does not (the joint fit, the delay test).
    pub max_delay_s: f64,
    pub numerator_order: usize,
    pub denominator_order: usize,
    pub trim_to_excitation: bool,
}
