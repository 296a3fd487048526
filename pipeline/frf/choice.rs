//! What the default estimator, `auto`, chooses for a run from its log and
//! the band, and what a log's command is (a sweep, a multisine, noise), so
//! that explicit settings the data contradict can be named.
//!
//! `auto` never averages Welch segments, which each see another part of a
//! sweep and bias the estimate. It takes the ETFE over the whole record
//! with a rectangular window (Y = G U + V bin by bin where the record starts
//! and ends at rest), and fits the record's transient beside each run's
//! model (`fit::transient`) where the ends do not rest within each signal's
//! own noise (`Ends`). The bins' noise level is read from what a first fit
//! leaves. Welch segments only give the coherence that masks unexcited
//! bins: long enough to resolve the band's lowest frequency twice over, at
//! least two in the record. `FrfChoice` resolves a run's plan; `excitation`
//! says what a command is. Why, with the evidence: docs/methods.md,
//! "Choosing the FRF estimator".

use super::{
    Detrend, Estimator, FrfError, FrfPlan, MIN_SEGMENT_LENGTH, Method, Window, ends_against_noise,
};

/// The Welch settings an explicit estimator gets for what the manifest
/// leaves out.
pub const DEFAULT_SEGMENT_LENGTH: usize = 8192;
pub const DEFAULT_OVERLAP: f64 = 0.5;

/// A record shorter than this many periods of the band's lowest frequency
/// cannot resolve it: the ETFE's bins are 1/T apart, and its noise level
/// is read from windows of 15 bins.
pub const MIN_PERIODS: f64 = 4.0;

/// The FRF settings as the manifest states them: the estimator (`auto`
/// unless it names one) and whichever of its settings it gives.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfRequest {
    pub estimator: Estimator,
    pub segment_length: Option<usize>,
    pub overlap: Option<f64>,
    pub window: Option<Window>,
    pub detrend: Option<Detrend>,
}

impl Default for FrfRequest {
    fn default() -> Self {
        Self {
            estimator: Estimator::Auto,
            segment_length: None,
            overlap: None,
            window: None,
            detrend: None,
        }
    }
}

impl From<FrfPlan> for FrfRequest {
    fn from(plan: FrfPlan) -> Self {
        Self {
            estimator: plan.method().into(),
            segment_length: Some(plan.segment_length()),
            overlap: Some(plan.overlap()),
            window: Some(plan.window()),
            detrend: Some(plan.detrend()),
        }
    }
}

/// How a record's ends stand: for the command and the displacement, the
/// end that is not at rest and by how many times the signal's noise
/// ([`ends_against_noise`]), or None where it rests at one level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ends {
    pub command: Option<(&'static str, f64)>,
    pub displacement: Option<(&'static str, f64)>,
}

impl Ends {
    /// The ends of a command `u` and displacement `y`, each end's window
    /// `w` samples long ([`super::rest_window`]).
    pub fn of(u: &[f64], y: &[f64], w: usize) -> Self {
        Self {
            command: ends_against_noise(u, w),
            displacement: ends_against_noise(y, w),
        }
    }

    pub fn at_rest(&self) -> bool {
        self.command.is_none() && self.displacement.is_none()
    }

    /// "at rest at both ends", or which signal moves at which end.
    pub fn describe(&self) -> String {
        let part = |name: &str, e: Option<(&str, f64)>| {
            e.map(|(end, ratio)| {
                format!(
                    "the {name} is not at rest at the record's {end} ({} times its noise)",
                    crate::units::format_number(ratio, 2)
                )
            })
        };
        let parts: Vec<String> = [
            part("command", self.command),
            part("displacement", self.displacement),
        ]
        .into_iter()
        .flatten()
        .collect();
        if parts.is_empty() {
            "the record is at rest at both ends".into()
        } else {
            parts.join(" and ")
        }
    }
}

/// The settings a run gets and why.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfChoice {
    pub plan: FrfPlan,
    /// Whether `auto` chose them (false: the manifest named the estimator).
    pub chosen: bool,
    pub ends: Ends,
    /// One sentence: what was chosen and why.
    pub reason: String,
}

impl FrfRequest {
    /// The settings of an explicit estimator, with Welch's defaults for
    /// what the manifest leaves out (8,192-sample Hann segments, half
    /// overlapping, the mean out); None for `auto`, which needs the log.
    fn explicit(&self) -> Option<Result<FrfPlan, FrfError>> {
        self.estimator.resolved().map(|method| {
            FrfPlan::new(
                method,
                self.explicit_segment_length(),
                self.overlap.unwrap_or(DEFAULT_OVERLAP),
                self.window.unwrap_or_default(),
                self.detrend.unwrap_or_default(),
            )
        })
    }

    /// An explicit estimator's segment length: the manifest's, else
    /// [`DEFAULT_SEGMENT_LENGTH`].
    fn explicit_segment_length(&self) -> usize {
        self.segment_length.unwrap_or(DEFAULT_SEGMENT_LENGTH)
    }

    /// The fewest samples a log must hold before its FRF is tried: an
    /// explicit plan's segment; for `auto`, the check is [`resolve`]'s,
    /// against the band.
    ///
    /// [`resolve`]: FrfRequest::resolve
    pub fn min_samples(&self) -> usize {
        match self.estimator.resolved() {
            Some(_) => self.explicit_segment_length(),
            None => MIN_SEGMENT_LENGTH,
        }
    }

    /// The settings of a run whose command is `u` and displacement `y`,
    /// sampled at `sample_rate_hz`, fitted over `band_hz`. An explicit
    /// estimator keeps the manifest's settings; `auto` takes the ETFE with
    /// a rectangular window (a window the manifest names is kept), the
    /// record's transient fitted beside the model unless both signals rest
    /// at one level at both ends within their noise, the noise level read
    /// from what a first fit leaves, and Welch segments for the coherence of
    /// the power of two nearest above twice the samples in a period of the
    /// band's lowest frequency, at most half the record.
    pub fn resolve(
        &self,
        u: &[f64],
        y: &[f64],
        sample_rate_hz: f64,
        band_hz: (f64, f64),
    ) -> Result<FrfChoice, FrfError> {
        let ends = Ends::of(u, y, super::rest_window(sample_rate_hz, band_hz.0));
        if let Some(plan) = self.explicit() {
            let plan = plan?;
            return Ok(FrfChoice {
                reason: format!("{} (the manifest's)", describe(&plan)),
                plan,
                chosen: false,
                ends,
            });
        }
        let n = u.len();
        let record_s = n as f64 / sample_rate_hz;
        let need_s = MIN_PERIODS / band_hz.0;
        if record_s < need_s {
            return Err(FrfError::BandBelowResolution {
                record_s,
                lo_hz: band_hz.0,
                need_s,
            });
        }
        let per_period = (2.0 * sample_rate_hz / band_hz.0).ceil() as usize;
        let segment_length = match self.segment_length {
            Some(l) => l,
            None => per_period
                .next_power_of_two()
                .min(n / 2)
                .max(MIN_SEGMENT_LENGTH),
        };
        let plan = FrfPlan::new(
            Method::Etfe,
            segment_length,
            self.overlap.unwrap_or(DEFAULT_OVERLAP),
            self.window.unwrap_or(Window::Rectangular),
            self.detrend.unwrap_or(Detrend::Mean),
        )?
        .with_model_noise(true);
        let plan = if ends.at_rest() {
            plan
        } else {
            plan.with_transient(band_hz.1)
        };
        let why = if plan.transient().is_some() {
            format!(
                "{}: its transient (the states' leakage, a drift's) is fitted beside the model and taken out; the noise level read from what a first fit leaves",
                ends.describe()
            )
        } else {
            format!(
                "{}, within their noise: Y = G U holds bin by bin; the noise level read from what a first fit leaves",
                ends.describe()
            )
        };
        Ok(FrfChoice {
            reason: format!("{} (auto: {why})", describe(&plan)),
            plan,
            chosen: true,
            ends,
        })
    }
}

/// The plan in words, as a run's page and the command line say it.
pub fn describe(plan: &FrfPlan) -> String {
    let window = match plan.window() {
        Window::Rectangular => "rectangular",
        Window::Hann => "Hann",
        Window::Hamming => "Hamming",
        Window::BlackmanHarris => "Blackman-Harris",
    };
    let segment_length = plan.segment_length();
    match plan.method() {
        Method::H1 => format!("Welch H1 over {segment_length}-sample {window} segments"),
        Method::H2 => format!("Welch H2 over {segment_length}-sample {window} segments"),
        Method::Etfe => format!(
            "ETFE over the whole record, {window} window{}, coherence from {segment_length}-sample segments",
            if plan.transient().is_some() {
                ", transient fitted"
            } else {
                ""
            },
        ),
        Method::Lpm => format!(
            "ETFE with the LPM's transient out, {window} window, coherence from {segment_length}-sample segments",
        ),
    }
}

/// What a command holds, as far as the FRF's choice cares.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Excitation {
    /// A sweep: its frequency moves one way through the record, from about
    /// `from_hz` to `to_hz`, each part of the record holding a narrow band.
    Sweep { from_hz: f64, to_hz: f64 },
    /// A multisine: its power on lines of equal height.
    Multisine,
    /// Broadband random noise (or a multisine whose period the record does
    /// not hold).
    Noise,
    /// Broadband, noise or a multisine: an FRF averaged over segments
    /// cannot tell.
    Broadband,
    /// A few lines only (sines, steps): too little for an FRF over a band.
    Narrowband,
    /// Too short, or no power, to tell.
    Unknown,
}

impl Excitation {
    /// In words, as results.json and the run's page give it.
    pub fn describe(&self) -> String {
        match *self {
            Excitation::Sweep { from_hz, to_hz } => {
                format!("a sweep from about {from_hz:.2} Hz to {to_hz:.2} Hz")
            }
            Excitation::Multisine => "a multisine".into(),
            Excitation::Noise => "broadband noise".into(),
            Excitation::Broadband => "a broadband signal (noise or a multisine)".into(),
            Excitation::Narrowband => "a few lines (sines or steps)".into(),
            Excitation::Unknown => "not told (too short or silent)".into(),
        }
    }

    /// The one-word kind: "sweep", "multisine", "noise", "broadband",
    /// "narrowband" or "unknown".
    pub fn kind(&self) -> &'static str {
        match self {
            Excitation::Sweep { .. } => "sweep",
            Excitation::Multisine => "multisine",
            Excitation::Noise => "noise",
            Excitation::Broadband => "broadband",
            Excitation::Narrowband => "narrowband",
            Excitation::Unknown => "unknown",
        }
    }
}

/// Blocks of the record whose spectra follow its frequency over time.
const BLOCKS: usize = 32;
/// The fewest samples a block must hold.
const MIN_BLOCK: usize = 64;
/// A block is active when its power is above this share of the loudest's.
const ACTIVE_SHARE: f64 = 1e-3;
/// A sweep's blocks peak at frequencies that never go back in at least
/// this share of their steps, cover at least this many of a block's bins
/// from first to last, and hold at least this share of their power within
/// [`PEAK_BINS`] bins of their peak (a sweep crosses a few bins in a
/// block; a real command's harmonics and noise hold the rest).
const SWEEP_ONE_WAY: f64 = 0.9;
const SWEEP_MIN_RANGE_BINS: f64 = 4.0;
const SWEEP_CONCENTRATION: f64 = 0.5;
const PEAK_BINS: usize = 4;
/// A whole-record bin holds a line when it is a local maximum above this
/// share of the largest; a multisine's lines vary less than this
/// coefficient of variation (a Gaussian signal's local maxima of |U|^2
/// about 0.7).
const LINE_SHARE: f64 = 1e-3;
const FLAT_CV: f64 = 0.35;

/// What the command `u` sampled at `sample_rate_hz` holds: a sweep when
/// the peaks of 32 blocks' spectra (a power of two long each,
/// spread over the record) move one way over a range of frequencies, each
/// block's power near its peak; otherwise, from the whole record's
/// periodogram when `periodogram` is one (an ETFE's |U|^2, its bins up to
/// where the FRF keeps them), a multisine when its lines are of one height,
/// noise when they scatter as a random signal's do, a few lines when there
/// are few; without it (an average over segments), broadband.
pub fn excitation(u: &[f64], sample_rate_hz: f64, periodogram: Option<&[f64]>) -> Excitation {
    let n = u.len();
    if n / BLOCKS < MIN_BLOCK || sample_rate_hz.is_nan() || sample_rate_hz <= 0.0 {
        return Excitation::Unknown;
    }
    // A power of two: a plan the FFT keeps for every log, never the
    // memory-hungry kind an arbitrary length can need.
    let block = 1usize << (n / BLOCKS).ilog2();
    let start = |b: usize| b * (n - block) / (BLOCKS - 1);
    let df = sample_rate_hz / block as f64;
    let mut transform = super::SegmentTransform::new(block);
    let mut out = transform.make_output();
    // (power, peak bin, share of the power within PEAK_BINS of the peak)
    // of each block.
    let stats: Vec<(f64, usize, f64)> = (0..BLOCKS)
        .map(|b| {
            transform.run(
                &u[start(b)..start(b) + block],
                None,
                Detrend::Mean,
                &mut out,
            );
            let power: Vec<f64> = out.iter().map(|x| x.norm_sqr()).collect();
            let total: f64 = power.iter().skip(1).sum();
            let peak = (1..power.len())
                .max_by(|&a, &b| power[a].total_cmp(&power[b]))
                .unwrap_or(1);
            let near: f64 = power
                [peak.saturating_sub(PEAK_BINS).max(1)..(peak + PEAK_BINS + 1).min(power.len())]
                .iter()
                .sum();
            (total, peak, if total > 0.0 { near / total } else { 0.0 })
        })
        .collect();
    let loudest = stats.iter().map(|s| s.0).fold(0.0, f64::max);
    if loudest.is_nan() || loudest <= 0.0 {
        return Excitation::Unknown;
    }
    let active: Vec<&(f64, usize, f64)> = stats
        .iter()
        .filter(|s| s.0 >= ACTIVE_SHARE * loudest)
        .collect();
    if active.len() >= 4 {
        let (first, last) = (active[0].1 as f64, active[active.len() - 1].1 as f64);
        let direction = (last - first).signum();
        let steps = active.len() - 1;
        let one_way = active
            .windows(2)
            .filter(|w| (w[1].1 as f64 - w[0].1 as f64) * direction >= 0.0)
            .count();
        let mut concentration: Vec<f64> = active.iter().map(|s| s.2).collect();
        concentration.sort_by(f64::total_cmp);
        if one_way as f64 >= SWEEP_ONE_WAY * steps as f64
            && (last - first).abs() >= SWEEP_MIN_RANGE_BINS
            && concentration[concentration.len() / 2] >= SWEEP_CONCENTRATION
        {
            return Excitation::Sweep {
                from_hz: first * df,
                to_hz: last * df,
            };
        }
    }
    let Some(periodogram) = periodogram else {
        return Excitation::Broadband;
    };
    let top = periodogram.iter().skip(1).copied().fold(0.0, f64::max);
    let lines: Vec<f64> = periodogram
        .windows(3)
        .skip(1)
        .filter(|w| w[1] >= LINE_SHARE * top && w[1] >= w[0] && w[1] >= w[2])
        .map(|w| w[1])
        .collect();
    if lines.len() < 8 {
        return Excitation::Narrowband;
    }
    let mean = lines.iter().sum::<f64>() / lines.len() as f64;
    let sd = (lines.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / lines.len() as f64).sqrt();
    if sd < FLAT_CV * mean {
        Excitation::Multisine
    } else {
        Excitation::Noise
    }
}
