//! A run's bins as the rig's fits read them: held in memory (a
//! [`FitData`]'s own), or kept off the heap by a store the run module
//! provides and read back a span at a time. A night's 600 spring FRFs are
//! 85 MB while the rig is fitted; kept in a store, a pass over them holds
//! a chunk's span. The numerical core reads a store only through
//! [`BinStore`], and gets back the bits it was given.

use std::borrow::Cow;
use std::ops::Range;
use std::sync::Arc;

use nalgebra::Complex;

use super::FitData;

/// Bins kept off the heap, read back by the key they were kept under.
pub trait BinStore: Send + Sync + std::fmt::Debug {
    /// Bins `span` (indices into the run's bins) of the run kept under
    /// `key` with `len` bins, with their amplitudes or without, bit for
    /// bit as they were kept.
    fn read(&self, key: usize, len: usize, amplitudes: bool, span: Range<usize>) -> Span<'static>;

    /// `data`'s bins kept beside the others (a coarse problem's own
    /// subset); their key, None where they cannot be kept.
    fn keep(&self, data: &FitData) -> Option<usize>;
}

/// Consecutive bins of a run: borrowed where the run holds them, read
/// from a store where it does not. Indexed by the run's own bin index.
#[derive(Debug, Clone)]
pub struct Span<'a> {
    /// The run's index of the first bin.
    pub start: usize,
    pub freq_hz: Cow<'a, [f64]>,
    pub h: Cow<'a, [Complex<f64>]>,
    /// E|dH|^2 at each bin.
    pub variance: Cow<'a, [f64]>,
    /// The displacement's amplitude (m) at each bin, where the run has one.
    pub amplitude_m: Option<Cow<'a, [f64]>>,
}

impl Span<'_> {
    #[inline(always)]
    pub fn freq(&self, i: usize) -> f64 {
        self.freq_hz[i - self.start]
    }

    #[inline(always)]
    pub fn h(&self, i: usize) -> Complex<f64> {
        self.h[i - self.start]
    }

    #[inline(always)]
    pub fn variance(&self, i: usize) -> f64 {
        self.variance[i - self.start]
    }

    #[inline(always)]
    pub fn amplitude(&self, i: usize) -> Option<f64> {
        self.amplitude_m.as_ref().map(|a| a[i - self.start])
    }

    /// The run's indices of the span's bins.
    pub fn indices(&self) -> Range<usize> {
        self.start..self.start + self.h.len()
    }
}

/// Where a run's bins are.
#[derive(Debug, Clone, Copy)]
pub enum Bins<'a> {
    /// In memory.
    Held {
        freq_hz: &'a [f64],
        h: &'a [Complex<f64>],
        variance: &'a [f64],
        amplitude_m: Option<&'a [f64]>,
    },
    /// In `store` under `key`: `len` bins, with amplitudes or without.
    Stored {
        store: &'a dyn BinStore,
        key: usize,
        len: usize,
        amplitudes: bool,
    },
}

impl<'a> Bins<'a> {
    /// Bins held in memory.
    pub fn held(
        freq_hz: &'a [f64],
        h: &'a [Complex<f64>],
        variance: &'a [f64],
        amplitude_m: Option<&'a [f64]>,
    ) -> Self {
        Bins::Held {
            freq_hz,
            h,
            variance,
            amplitude_m,
        }
    }

    /// The number of bins.
    pub fn len(&self) -> usize {
        match self {
            Bins::Held { h, .. } => h.len(),
            Bins::Stored { len, .. } => *len,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The lengths of the frequencies, H and the variances, which a fit
    /// checks agree (a store keeps them together).
    pub fn lengths(&self) -> (usize, usize, usize) {
        match self {
            Bins::Held {
                freq_hz,
                h,
                variance,
                ..
            } => (freq_hz.len(), h.len(), variance.len()),
            Bins::Stored { len, .. } => (*len, *len, *len),
        }
    }

    /// Whether the bins carry the displacement's amplitude.
    pub fn has_amplitudes(&self) -> bool {
        match self {
            Bins::Held { amplitude_m, .. } => amplitude_m.is_some(),
            Bins::Stored { amplitudes, .. } => *amplitudes,
        }
    }

    /// The bins `span`.
    pub fn span(&self, span: Range<usize>) -> Span<'a> {
        match *self {
            Bins::Held {
                freq_hz,
                h,
                variance,
                amplitude_m,
            } => Span {
                start: span.start,
                freq_hz: Cow::Borrowed(&freq_hz[span.clone()]),
                h: Cow::Borrowed(&h[span.clone()]),
                variance: Cow::Borrowed(&variance[span.clone()]),
                amplitude_m: amplitude_m.map(|a| Cow::Borrowed(&a[span])),
            },
            Bins::Stored {
                store,
                key,
                len,
                amplitudes,
            } => store.read(key, len, amplitudes, span),
        }
    }

    /// Every bin.
    pub fn all(&self) -> Span<'a> {
        self.span(0..self.len())
    }
}

/// A [`FitData`]'s bins moved to a store, with what a fit reads beside
/// them.
#[derive(Debug, Clone)]
pub struct StoredFit {
    pub store: Arc<dyn BinStore>,
    pub key: usize,
    pub len: usize,
    pub amplitudes: bool,
    /// [`FitData::bin_hz`].
    pub bin_hz: f64,
    /// [`FitData::lag`].
    pub lag: usize,
}

impl StoredFit {
    pub fn bins(&self) -> Bins<'_> {
        Bins::Stored {
            store: self.store.as_ref(),
            key: self.key,
            len: self.len,
            amplitudes: self.amplitudes,
        }
    }
}

impl FitData {
    /// The bins, held.
    pub fn bins(&self) -> Bins<'_> {
        Bins::held(
            &self.freq_hz,
            &self.h,
            &self.variance,
            self.amplitude_m.as_deref(),
        )
    }
}

/// A store in memory, for tests of the stored path: each run's bins
/// copied, read back by span.
#[cfg(test)]
#[derive(Debug, Default)]
pub struct MemoryStore {
    runs: std::sync::Mutex<Vec<FitData>>,
}

#[cfg(test)]
impl BinStore for MemoryStore {
    fn read(&self, key: usize, _: usize, amplitudes: bool, span: Range<usize>) -> Span<'static> {
        let d = &self.runs.lock().unwrap()[key];
        Span {
            start: span.start,
            freq_hz: Cow::Owned(d.freq_hz[span.clone()].to_vec()),
            h: Cow::Owned(d.h[span.clone()].to_vec()),
            variance: Cow::Owned(d.variance[span.clone()].to_vec()),
            amplitude_m: (d.amplitude_m.as_ref())
                .filter(|_| amplitudes)
                .map(|a| Cow::Owned(a[span].to_vec())),
        }
    }

    fn keep(&self, data: &FitData) -> Option<usize> {
        let mut runs = self.runs.lock().unwrap();
        runs.push(data.clone());
        Some(runs.len() - 1)
    }
}
