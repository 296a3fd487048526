//! Published numbers beside the recomputed ones: each reference of the
//! manifest read back from the results being written, so the comparison is
//! of what a reader sees.

use crate::manifest::{Campaign, CompareMode, Quantity};
use crate::results::{Comparison, ComparisonStatus, Results};

/// The value of a quantity, read back from the results being written (so the
/// comparison is of what a reader sees).
fn lookup(q: &Quantity, r: &Results) -> Option<f64> {
    match q {
        Quantity::Rig(name) => {
            let rig = r.rig.as_ref()?;
            Some(match name.as_str() {
                "beta1" => rig.beta1.value,
                "R1" => rig.R1.value,
                "a1b0" => rig.a1b0.value,
                "a2" => rig.a2.value,
                "a3" => rig.a3.value,
                "valve_time_constant_ms" => rig.valve_time_constant_ms.value,
                _ => return None,
            })
        }
        Quantity::PerSpring { run, name } => {
            let s = r.rig.as_ref()?.per_spring.iter().find(|s| &s.run == run)?;
            Some(match name.as_str() {
                "R2" => s.R2.value,
                "R3" => s.R3.value,
                "a1b0" => s.a1b0.value,
                "a2" => s.a2.value,
                "a3" => s.a3.value,
                _ => return None,
            })
        }
        Quantity::Run { run, name } => {
            let rr = r.runs.iter().find(|x| &x.id == run)?;
            match name.as_str() {
                "a1b0" => rr.a1b0,
                "natural_frequency_hz" => rr.natural_frequency_hz,
                "nrmse_pct" => rr.validation.as_ref().map(|v| v.nrmse_pct),
                "nae_pct" => rr.validation.as_ref().map(|v| v.nae_pct),
                _ => None,
            }
        }
        Quantity::Ccf { run, name } => {
            let c = r.ccf.iter().find(|c| &c.run == run)?;
            Some(match name.as_str() {
                "C1" => c.C1,
                "C2" => c.C2,
                "C3" => c.C3,
                "C4" => c.C4,
                "C5" => c.C5,
                _ => return None,
            })
        }
    }
}

pub fn compare(campaign: &Campaign, results: &Results) -> Vec<Comparison> {
    campaign
        .references
        .iter()
        .map(|refp| {
            let computed = lookup(&refp.quantity, results);
            let rel_diff = computed.map(|c| {
                let c = match refp.compare {
                    CompareMode::Signed => c,
                    CompareMode::Magnitude => c.abs(),
                };
                (c - refp.published) / refp.published.abs()
            });
            let flag = rel_diff.is_some_and(|d| d.abs() * 100.0 > refp.tolerance_pct);
            let status = match rel_diff {
                None => ComparisonStatus::NotComputed,
                Some(_) if flag => ComparisonStatus::Differs,
                Some(_) => ComparisonStatus::Agrees,
            };
            Comparison {
                quantity: refp.quantity.to_string(),
                published: refp.published,
                computed,
                rel_diff,
                flag,
                compare: refp.compare,
                tolerance_pct: refp.tolerance_pct,
                source: refp.source.clone(),
                status,
            }
        })
        .collect()
}
