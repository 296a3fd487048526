//! The identification section of either manifest kind, checked into an
//! [`IdentificationPlan`]: the stages' own settings (the FRF's, the fit's, the
//! delay's), each default decided here once. Problems are reported through
//! `bad(key path, message)`, never stopping at the first.

use super::checks::{check_band, positive};
use super::keypath::KeyPath;
use super::raw::{DelayMode, Identification};
use crate::fit::DelayPlan;
use crate::frf::FrfRequest;
use crate::identify::IdentificationPlan;

pub(super) fn check_identification(
    id: &Identification,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> IdentificationPlan {
    check_band(id.band_hz, &path.key("band_hz"), bad);
    if !(0.0..1.0).contains(&id.coherence_min) {
        bad(
            path.key("coherence_min"),
            format!("must be in [0, 1) (got {})", id.coherence_min),
        );
    }
    let frf = path.key("frf");
    if let Some(l) = id.frf.segment_length
        && l < crate::frf::MIN_SEGMENT_LENGTH
    {
        bad(
            frf.key("segment_length"),
            format!(
                "must be at least {} samples (got {l})",
                crate::frf::MIN_SEGMENT_LENGTH
            ),
        );
    }
    if let Some(o) = id.frf.overlap
        && !(0.0..1.0).contains(&o)
    {
        bad(frf.key("overlap"), format!("must be in [0, 1) (got {o})"));
    }
    let d = &id.delay;
    let delay = match d.mode {
        DelayMode::None => DelayPlan::None,
        DelayMode::Fixed => {
            if !(d.value_s.is_finite() && d.value_s >= 0.0) {
                bad(
                    path.key("delay").key("value_s"),
                    format!("must be a non-negative delay (got {})", d.value_s),
                );
            }
            DelayPlan::Fixed { delay_s: d.value_s }
        }
        DelayMode::Fit => DelayPlan::Fit { max_s: d.max_s },
    };
    positive(d.max_s, &path.key("delay").key("max_s"), bad);
    if let Some(v0) = id.joint.friction_smoothing_m_per_s {
        positive(
            v0,
            &path.key("joint").key("friction_smoothing_m_per_s"),
            bad,
        );
    }
    if id.model.denominator == 0 || id.model.numerator > id.model.denominator {
        bad(
            path.key("model"),
            format!(
                "needs 1 <= denominator and numerator <= denominator (got {}/{})",
                id.model.numerator, id.model.denominator
            ),
        );
    }
    IdentificationPlan {
        band_hz: (id.band_hz[0], id.band_hz[1]),
        coherence_min: id.coherence_min,
        frf: FrfRequest {
            estimator: id.frf.estimator,
            segment_length: id.frf.segment_length,
            overlap: id.frf.overlap,
            window: id.frf.window,
            detrend: id.frf.detrend,
        },
        intersample: id.command_intersample,
        delay,
        max_delay_s: d.max_s,
        numerator_order: id.model.numerator,
        denominator_order: id.model.denominator,
        trim_to_excitation: id.trim_to_excitation,
    }
}
