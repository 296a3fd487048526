//! What each run gives the rig's identification (Fig. 6 and the joint fit):
//! its model with what its fit was given, or why it has none. `rig.rs` and
//! `joint.rs` both read it; neither owns it.

use std::sync::Arc;

use super::log_stage::LogStageError;
use crate::fit::adequacy::Adequacy;
use crate::identify::FitData;
use crate::identify::bins::{Bins, StoredFit};
use crate::lti::TransferFunction;
use crate::manifest::RunPlan;

/// What a run gives the rig's identification.
#[derive(Debug, Clone)]
pub enum RigInput {
    /// Its model and what its fit was given.
    Estimate(Box<Evidence>),
    /// Its first stage failed.
    Failed(Arc<LogStageError>),
    /// A validation run's FRFs, for the joint fit
    /// (`identification.joint.include_validation`).
    Validation(Box<ValidationEvidence>),
    /// Nothing (a run without a model of its own).
    Nothing,
}

/// A run's model, and what the joint fit needs of it.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Evidence {
    /// Its transfer function, with the covariance of (n0, d1, d0) when
    /// fitted.
    pub tf: TransferFunction,
    pub cov: Option<[[f64; 3]; 3]>,
    /// The bins its fit was given (None for a published model), without
    /// the input's spectrum ([`FitData::for_rig`]).
    pub data: Option<FitData>,
    /// Where `data`'s bins are when the run module has moved them off the
    /// heap (`data` is then None). Never cached: the cache keeps a run's
    /// evidence before its bins move, and a store lasts one job.
    #[serde(skip)]
    pub stored: Option<StoredFit>,
    /// Its own fit's adequacy tests.
    pub adequacy: Option<Adequacy>,
    pub sample_rate_hz: Option<f64>,
    /// What its own warnings found wrong (`log_stage::LogStage::cause`).
    #[serde(default)]
    pub cause: Option<String>,
    /// Whether its displacement showed seal friction's harmonics
    /// (`log_stage::LogStage::friction_signature`).
    #[serde(default)]
    pub friction_signature: bool,
    /// A spring that stiffens (`frf::SpringForce::stiffens`): the cubic
    /// term (N/m^3) its force against its displacement gives.
    #[serde(default)]
    pub spring_cubic_n_per_m3: Option<f64>,
    /// A spring run's force against its displacement: the stiffness its
    /// load cell gives (N/m) and the displacement's amplitude (m).
    #[serde(default)]
    pub load_cell: Option<(f64, f64)>,
    /// How its displacement's gain changes with amplitude where its sweep
    /// is slow (`log_stage::LogStage::slow`).
    #[serde(default)]
    pub slow: Option<crate::frf::SlowCubic>,
}

impl Evidence {
    /// The bins its fit was given, wherever they are, with the FRF's grid
    /// spacing (Hz) and independent lag (bins).
    pub fn bins(&self) -> Option<(Bins<'_>, f64, usize)> {
        match (&self.data, &self.stored) {
            (Some(d), _) => Some((d.bins(), d.bin_hz, d.lag)),
            (None, Some(s)) => Some((s.bins(), s.bin_hz, s.lag)),
            (None, None) => None,
        }
    }

    /// Its bins moved off the heap by `keep`; where `keep` cannot take
    /// them (None) they stay.
    pub fn move_bins(&mut self, keep: impl FnOnce(&FitData) -> Option<StoredFit>) {
        if let Some(stored) = self.data.as_ref().and_then(keep) {
            self.data = None;
            self.stored = Some(stored);
        }
    }
}

/// What a validation run gives the joint fit: the band's bins of its x1/u
/// and, with a force channel, of its f/u (each with the coherence test the
/// identification runs pass), without their input spectra
/// ([`FitData::for_rig`]).
#[derive(Debug, Clone)]
pub struct ValidationEvidence {
    pub displacement: FitData,
    pub force: Option<FitData>,
    pub sample_rate_hz: f64,
    /// The log's SHA-256, which the second pass's own read of the log must
    /// find again (the rig was fitted to these bytes).
    pub sha256: String,
}

/// Whether the displacements' harmonics of the command are the load's:
/// some loaded run has them and the unloaded runs, read, have none. Seal
/// friction acts on the piston whether or not a specimen loads it (most
/// where the chamber's force is least, unloaded); the valve's flow law
/// acts only on the force, so a run without a specimen has none of it.
pub fn harmonics_under_load_only(evidence: &[(&RunPlan, &Evidence)]) -> bool {
    let read = |e: &Evidence| e.slow.is_some();
    let mut unloaded = evidence
        .iter()
        .filter(|(p, e)| !p.specimen.loads() && read(e))
        .peekable();
    unloaded.peek().is_some()
        && !unloaded.any(|(_, e)| e.friction_signature)
        && evidence
            .iter()
            .any(|(p, e)| p.specimen.loads() && e.friction_signature)
}
