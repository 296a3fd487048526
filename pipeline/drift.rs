//! Rig drift: each campaign adds its identified rig to the rig's history,
//! and a parameter raises an alarm when it moves away from its recent past
//! by more than its uncertainty allows, so that a nightly job can page
//! someone when a servo-valve degrades.
//!
//! For each of beta1, a1b0 (referred to P = 1), a2 and a3, with m its median
//! over the last K = `window` entries (at least [`MIN_HISTORY`]): alarm when
//! |x - m| > N max(sigma_x, sigma_h), N = `threshold`, sigma_x the
//! campaign's own std of x and sigma_h the history's scatter, measured on
//! night-to-night differences (1.4826 times their MAD, over sqrt 2) so that
//! a steady drift does not widen its own threshold. The night's actuator
//! delay is checked the same way, with a floor. Why the differences:
//! docs/methods.md, "The drift rule".

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Fewest earlier entries a parameter is checked against.
pub const MIN_HISTORY: usize = 3;

/// The parameters checked, in this order: the rig's four, and the night's
/// actuator delay ([`Entry::delay_s`]) where the night measured one.
pub const PARAMETERS: [&str; 5] = ["beta1", "a1b0", "a2", "a3", "delay"];

/// The least move of the delay that raises its alarm (s). The delay has no
/// stated std of its own, so its limit is the history's scatter (about
/// 0.07 ms between nights of 20 s sweeps with 0.1 mm of LVDT noise,
/// `tests/drift.rs`), which a handful of nights can understate by chance;
/// the floor keeps a stable rig from alarming on such a night. A quarter of
/// a millisecond is a fraction of the delay an RTHS loop's compensation is
/// tuned to (tens of milliseconds for the paper's actuator).
pub const DELAY_FLOOR_S: f64 = 0.25e-3;

/// The history table's columns, in order: those of [`Entry`].
pub const TABLE_COLUMNS: [&str; 15] = [
    "rig",
    "campaign",
    "date",
    "inputs_sha256",
    "results_sha256",
    "p_gain",
    "beta1",
    "beta1_std",
    "a1b0",
    "a1b0_std",
    "a2",
    "a2_std",
    "a3",
    "a3_std",
    "servoid_version",
];

/// Columns written after those, which a table written before them lacks
/// (read as absent).
pub const OPTIONAL_TABLE_COLUMNS: [&str; 2] = ["delay_s", "logs_sha256"];

/// One campaign's rig in the history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Entry {
    /// The rig's name (the history is kept per rig).
    pub rig: String,
    pub campaign: String,
    /// The latest of the campaign's run dates, when its runs have dates.
    pub date: Option<String>,
    /// SHA-256 over what the campaign's results come from (its manifest and
    /// logs, and the servoid version): a rerun of the same campaign replaces
    /// its own entry instead of adding one.
    pub inputs_sha256: String,
    /// SHA-256 of the campaign's results.json.
    pub results_sha256: String,
    /// The servoid that wrote the entry.
    pub servoid_version: String,
    /// The P gain at which `a1b0` is stated.
    pub p_gain: f64,
    pub beta1: f64,
    pub beta1_std: Option<f64>,
    pub a1b0: f64,
    pub a1b0_std: Option<f64>,
    pub a2: f64,
    pub a2_std: Option<f64>,
    pub a3: f64,
    pub a3_std: Option<f64>,
    /// The night's actuator delay by cross-correlation (s): the median over
    /// its no-specimen runs, or over all its runs that measured one when it
    /// has none (`tracking::xcorr_delay`). None in entries written before
    /// servoid measured it, and for a night without logs.
    #[serde(default)]
    pub delay_s: Option<f64>,
    /// SHA-256 over the night's log hashes, sorted (whatever the runs are
    /// called): the same campaign's night analysed again on the same logs
    /// (and date) with a corrected manifest replaces this entry. None for a night without logs and in
    /// entries written before servoid kept it.
    #[serde(default)]
    pub logs_sha256: Option<String>,
}

impl Entry {
    /// A parameter's value and std, a1b0 referred to P = 1; None for the
    /// delay of an entry without one (and for an unknown name).
    pub fn parameter(&self, name: &str) -> Option<(f64, Option<f64>)> {
        let per_p = |v: f64| v / self.p_gain;
        Some(match name {
            "beta1" => (self.beta1, self.beta1_std),
            "a1b0" => (per_p(self.a1b0), self.a1b0_std.map(per_p)),
            "a2" => (self.a2, self.a2_std),
            "a3" => (self.a3, self.a3_std),
            "delay" => (self.delay_s?, None),
            _ => return None,
        })
    }
}

/// The alarm rule's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rule {
    /// K: how many recent entries the median is taken over.
    pub window: usize,
    /// N: how many standard deviations a move may be.
    pub threshold: f64,
}

/// One parameter checked against its history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Check {
    pub parameter: String,
    /// This campaign's value (a1b0 at P = 1) and standard deviation.
    pub value: f64,
    pub std: Option<f64>,
    /// Earlier entries it was checked against (at most the window).
    pub entries: usize,
    /// The median of those entries; null with fewer than MIN_HISTORY.
    pub median: Option<f64>,
    /// The history's scatter sigma_h.
    pub history_scatter: Option<f64>,
    /// N max(sigma_x, sigma_h): how far the value may move.
    pub limit: Option<f64>,
    /// x - median.
    pub deviation: Option<f64>,
    pub alarm: bool,
}

/// Check each parameter of `current` against `earlier` (this rig's entries
/// before it, oldest first). The delay is checked where `current` has one,
/// against the earlier entries that have one, and its limit is at least
/// [`DELAY_FLOOR_S`].
pub fn check(earlier: &[Entry], current: &Entry, rule: Rule) -> Vec<Check> {
    let window = &earlier[earlier.len().saturating_sub(rule.window)..];
    PARAMETERS
        .iter()
        .filter_map(|&name| {
            let (value, std) = current.parameter(name)?;
            let past: Vec<f64> = window
                .iter()
                .filter_map(|e| e.parameter(name).map(|p| p.0))
                .collect();
            let mut c = Check {
                parameter: name.to_string(),
                value,
                std,
                entries: past.len(),
                median: None,
                history_scatter: None,
                limit: None,
                deviation: None,
                alarm: false,
            };
            if past.len() >= MIN_HISTORY {
                let median = median(&past);
                let scatter = difference_scatter(&past);
                let mut limit = rule.threshold * std.unwrap_or(0.0).max(scatter);
                if name == "delay" {
                    limit = limit.max(DELAY_FLOOR_S);
                }
                let deviation = value - median;
                c.median = Some(median);
                c.history_scatter = Some(scatter);
                c.limit = Some(limit);
                c.deviation = Some(deviation);
                c.alarm = deviation.abs() > limit;
            }
            Some(c)
        })
        .collect()
}

/// The median (mean of the middle two for an even count).
fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// sigma_h: the scatter of one value about a smooth trend, from successive
/// differences (whose std is sqrt 2 sigma for independent noise), robustly.
fn difference_scatter(v: &[f64]) -> f64 {
    let d: Vec<f64> = v.windows(2).map(|w| w[1] - w[0]).collect();
    let m = median(&d);
    let abs: Vec<f64> = d.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median(&abs) / std::f64::consts::SQRT_2
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(beta1: f64, std: f64) -> Entry {
        Entry {
            rig: "r".into(),
            campaign: "c".into(),
            date: None,
            inputs_sha256: String::new(),
            results_sha256: String::new(),
            servoid_version: String::new(),
            p_gain: 2.0,
            beta1,
            beta1_std: Some(std),
            a1b0: 4.8e9,
            a1b0_std: Some(1e6),
            a2: 7.9e5,
            a2_std: Some(300.0),
            a3: 16.1,
            a3_std: Some(0.01),
            delay_s: None,
            logs_sha256: None,
        }
    }

    #[test]
    fn a_steady_drift_is_caught_when_it_passes_the_limit() {
        // beta1 falls 1 % of 267 a night with a stated std of 1 % of its
        // value. The differences are all alike, so sigma_h = 0 and the
        // limit is 4 x 1 % x beta1_n. Up to K = 10 earlier nights, the
        // median is the value of night (n - 1)/2, so the deviation is
        // 2.67 (n + 1)/2: night 6 gives 9.345 < 0.04 x 250.98 = 10.04,
        // night 7 gives 10.68 > 0.04 x 248.31 = 9.93. The first alarm is
        // night 7, not before.
        let nights: Vec<Entry> = (0..12)
            .map(|n| {
                let b = 267.0 * (1.0 - 0.01 * n as f64);
                entry(b, 0.01 * b)
            })
            .collect();
        let rule = Rule {
            window: 10,
            threshold: 4.0,
        };
        let alarms: Vec<usize> = (0..nights.len())
            .filter(|&n| check(&nights[..n], &nights[n], rule)[0].alarm)
            .collect();
        assert_eq!(alarms, (7..12).collect::<Vec<_>>());
        let c = &check(&nights[..7], &nights[7], rule)[0];
        assert!((c.median.unwrap() - 267.0 * 0.97).abs() < 1e-9);
        assert!((c.deviation.unwrap() + 2.67 * 4.0).abs() < 1e-9);
        assert!(c.history_scatter.unwrap() < 1e-9);
        assert_eq!(c.entries, 7);
        // With a full window the median lags 5.5 nights.
        let c = &check(&nights[..11], &nights[11], rule)[0];
        assert_eq!(c.entries, 10);
        assert!((c.median.unwrap() - 267.0 * (1.0 - 0.01 * 5.5)).abs() < 1e-9);
    }

    #[test]
    fn a_stable_rig_never_raises_one_and_a1b0_is_referred_to_p_1() {
        // Values jitter by about their stated std: never 4 std off.
        let jitter = [
            0.3, -0.8, 0.5, 1.1, -0.2, -1.0, 0.7, 0.0, -0.4, 0.9, -0.6, 0.2,
        ];
        let nights: Vec<Entry> = jitter.iter().map(|j| entry(267.0 + j * 0.1, 0.1)).collect();
        let rule = Rule {
            window: 10,
            threshold: 4.0,
        };
        for n in 0..nights.len() {
            let checks = check(&nights[..n], &nights[n], rule);
            assert!(checks.iter().all(|c| !c.alarm), "night {n}: {checks:?}");
            // Exact: the entries' a1b0 is 2.4e9 at P = 1, referred to P = 1.
            assert_eq!(checks[1].value, 2.4e9, "a1b0 at P = 1");
        }
        // Too little history: no check at all.
        let c = check(&nights[..2], &nights[2], rule);
        assert!(c.iter().all(|c| c.median.is_none() && !c.alarm));
    }

    #[test]
    fn the_history_scatter_ignores_a_trend_but_not_noise() {
        let ramp: Vec<f64> = (0..10).map(|k| 100.0 + 3.0 * k as f64).collect();
        assert!(difference_scatter(&ramp).abs() < 1e-12);
        // Alternating +-1 about a constant.
        let alt: Vec<f64> = (0..9)
            .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        // d = [-2, 2, -2, 2, -2, 2, -2, 2]: median 0, |d| all 2, MAD 2.
        let want = 1.4826 * 2.0 / std::f64::consts::SQRT_2;
        assert!((difference_scatter(&alt) - want).abs() < 1e-12);
    }
}
