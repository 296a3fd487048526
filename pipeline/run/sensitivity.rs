//! The campaign's stiffness sensitivity (`analysis::sensitivity`), with
//! its Monte Carlo cached under a key of everything that decides it (the
//! rig to the last bit, the noise profile, the no-specimen log's hash, the
//! identification and Monte Carlo settings), so a rerun with the same rig
//! does not repeat it.

use super::cache::{self, Cache};
use crate::analysis::sensitivity::{McUnavailable, NoiseSource, run_monte_carlo};
use crate::manifest::{Campaign, MonteCarloSettings};
use crate::model::RigParams;
use crate::report::WriteError;
use crate::results::{Results, SensitivityResult};
use crate::sensitivity::montecarlo::MonteCarlo;

/// The sensitivity of a campaign whose rig is `rig`; `noise` the first
/// no-specimen run's FRF noise. None when the rig allows no sweep.
pub(super) fn sensitivity(
    campaign: &Campaign,
    rig: &RigParams,
    results: &Results,
    noise: Option<&NoiseSource>,
    cache: Option<&Cache>,
) -> Result<Option<SensitivityResult>, WriteError> {
    let range = campaign.sensitivity.range.n_per_m(rig.a2_n_per_m);
    let monte_carlo = || -> Result<_, WriteError> {
        let Some(mc) = &campaign.sensitivity.monte_carlo else {
            return Ok(None);
        };
        Ok(Some(match noise {
            None => Err("the Monte Carlo replays a no-specimen run's logged command with its measured noise, and this campaign has no no-specimen log that was fitted".to_string()),
            Some(source) => cached_monte_carlo(campaign, rig, source, range, mc, cache)?
                .map_err(|why| why.to_string()),
        }))
    };
    crate::analysis::sensitivity::sensitivity(campaign, rig, results, noise, range, monte_carlo)
}

/// The Monte Carlo from the cache, or run and cached; Err says why it
/// cannot run (recorded in the results, not a failure of the campaign).
fn cached_monte_carlo(
    campaign: &Campaign,
    rig: &RigParams,
    source: &NoiseSource,
    range: (f64, f64),
    mc: &MonteCarloSettings,
    cache: Option<&Cache>,
) -> Result<Result<MonteCarlo, McUnavailable>, WriteError> {
    let key = cache::key(&[
        &"monte carlo",
        rig,
        source,
        &campaign.identification,
        mc,
        &range,
    ]);
    if let Some(hit) = cache.and_then(|c| c.lookup::<MonteCarlo>(&key)) {
        return Ok(Ok(hit));
    }
    let outcome = run_monte_carlo(campaign, rig, source, range, mc);
    if let (Some(c), Ok(m)) = (cache, &outcome) {
        c.store(&key, m)?;
    }
    Ok(outcome)
}
