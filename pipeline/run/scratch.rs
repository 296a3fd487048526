//! What a job need not hold, off the heap while it lasts: an unnamed file
//! in the output folder (gone when the job ends, however it ends, and
//! never among the folder's outputs). The identification runs' bins are
//! written as each run's first pass ends and read back a span at a time by
//! the rig's fits (`identify::bins`): a run's bins are its columns one
//! after another (frequency, H as Re and Im, E|dH|^2, and its amplitudes
//! where it has them), their bits as computed, in the machine's byte
//! order, since the file lasts no longer than the job. A run's parked
//! parts (`results::Parked`) are their bytes as given.

use std::borrow::Cow;
use std::fs::File;
use std::io;
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use nalgebra::Complex;

use crate::identify::FitData;
use crate::identify::bins::{BinStore, Span, StoredFit};
use crate::results::PartStore;

/// The scratch file of one job.
#[derive(Debug)]
pub(super) struct Scratch {
    file: File,
    /// The folder it is in, to name in an error.
    dir: PathBuf,
    /// The bytes written so far (a multiple of 8, so bins' keys count
    /// f64s): where the next record starts.
    end: Mutex<u64>,
}

impl Scratch {
    /// A scratch file in `dir`, None where it cannot be made (what would
    /// have gone there stays in memory).
    pub(super) fn new(dir: &Path) -> Option<Arc<Self>> {
        let file = tempfile::tempfile_in(dir).ok()?;
        Some(Arc::new(Self {
            file,
            dir: dir.to_path_buf(),
            end: Mutex::new(0),
        }))
    }

    /// `data`'s bins written to the file, to be read back from `self`.
    pub(super) fn keep(self: &Arc<Self>, data: &FitData) -> io::Result<StoredFit> {
        Ok(StoredFit {
            store: Arc::clone(self) as Arc<dyn BinStore>,
            key: self.write_bins(data)?,
            len: data.h.len(),
            amplitudes: data.amplitude_m.is_some(),
            bin_hz: data.bin_hz,
            lag: data.lag,
        })
    }

    /// `data`'s bins written to the file; their key is where they start
    /// (in f64s).
    fn write_bins(&self, data: &FitData) -> io::Result<usize> {
        let n = data.h.len();
        let amplitude = data.amplitude_m.as_deref();
        let mut values = Vec::with_capacity(n * 5);
        values.extend_from_slice(&data.freq_hz);
        values.extend(data.h.iter().flat_map(|h| [h.re, h.im]));
        values.extend_from_slice(&data.variance);
        values.extend_from_slice(amplitude.unwrap_or_default());
        let at = self.write(bytemuck::cast_slice(&values))?;
        Ok((at / 8) as usize)
    }

    /// A part's bytes written to the file, with the store to read them back
    /// from and where they start.
    pub(super) fn keep_part(
        self: &Arc<Self>,
        bytes: &[u8],
    ) -> io::Result<(Arc<dyn PartStore>, u64)> {
        let at = self.write(bytes)?;
        Ok((Arc::clone(self) as Arc<dyn PartStore>, at))
    }

    /// `bytes` written at the file's end, padded to a multiple of 8; where
    /// they start.
    fn write(&self, bytes: &[u8]) -> io::Result<u64> {
        let at = {
            let mut end = self.end.lock().unwrap_or_else(|e| e.into_inner());
            let at = *end;
            *end += (bytes.len() as u64).next_multiple_of(8);
            at
        };
        self.file.write_all_at(bytes, at)?;
        Ok(at)
    }

    /// The `n` f64s from the file's `at`-th.
    fn column(&self, at: usize, n: usize) -> Vec<f64> {
        let mut values = vec![0.0_f64; n];
        self.read_into(bytemuck::cast_slice_mut(&mut values), (at * 8) as u64);
        values
    }

    /// Fill `bytes` from the file at `at`. Panics where it cannot be read
    /// back: it was written in the output folder moments before, and what
    /// reads it has no way to go on without it.
    fn read_into(&self, bytes: &mut [u8], at: u64) {
        if let Err(e) = self.file.read_exact_at(bytes, at) {
            panic!(
                "{}: what the job kept in a scratch file there cannot be read back: {e}",
                self.dir.display()
            );
        }
    }
}

impl PartStore for Scratch {
    fn read(&self, at: u64, len: usize) -> Vec<u8> {
        let mut bytes = vec![0; len];
        self.read_into(&mut bytes, at);
        bytes
    }
}

impl BinStore for Scratch {
    fn read(&self, key: usize, len: usize, amplitudes: bool, span: Range<usize>) -> Span<'static> {
        // The columns' starts: frequency, H (two f64 a bin), E|dH|^2, amplitude.
        let (s, n) = (span.start, span.len());
        let h: Vec<f64> = self.column(key + len + 2 * s, 2 * n);
        Span {
            start: s,
            freq_hz: Cow::Owned(self.column(key + s, n)),
            h: Cow::Owned(
                h.chunks_exact(2)
                    .map(|v| Complex::new(v[0], v[1]))
                    .collect(),
            ),
            variance: Cow::Owned(self.column(key + 3 * len + s, n)),
            amplitude_m: amplitudes.then(|| Cow::Owned(self.column(key + 4 * len + s, n))),
        }
    }

    fn keep(&self, data: &FitData) -> Option<usize> {
        self.write_bins(data).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What is read back is what was written, to the bit, span by span
    /// and run by run.
    #[test]
    fn bins_read_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let scratch = Scratch::new(dir.path()).unwrap();
        let run = |n: usize, seed: f64, amplitude: bool| FitData {
            freq_hz: (0..n).map(|i| 0.5 + i as f64 / 120.0).collect(),
            h: (0..n)
                .map(|i| Complex::new((seed * i as f64).sin(), -1.0 / (1.0 + i as f64)))
                .collect(),
            variance: (0..n).map(|i| 1e-9 * (1.0 + seed * i as f64)).collect(),
            suu: Vec::new(),
            bin_hz: 1.0 / 120.0,
            lag: 1,
            amplitude_m: amplitude.then(|| (0..n).map(|i| 1e-3 / (1.0 + i as f64)).collect()),
        };
        let (a, b) = (run(300, 0.37, false), run(41, 1.9, true));
        let (ka, kb) = (scratch.keep(&a).unwrap(), scratch.keep(&b).unwrap());
        assert_eq!((ka.key, kb.key, kb.len), (0, 4 * 300, 41));
        assert!(!ka.amplitudes && kb.amplitudes);
        let got = ka.bins().span(17..260);
        assert_eq!(got.indices(), 17..260);
        assert!(got.amplitude_m.is_none());
        for i in got.indices() {
            assert_eq!(got.freq(i).to_bits(), a.freq_hz[i].to_bits());
            assert_eq!(got.h(i).re.to_bits(), a.h[i].re.to_bits());
            assert_eq!(got.h(i).im.to_bits(), a.h[i].im.to_bits());
            assert_eq!(got.variance(i).to_bits(), a.variance[i].to_bits());
        }
        let all = kb.bins().all();
        let amplitude = b.amplitude_m.as_ref().unwrap();
        for (i, &x) in amplitude.iter().enumerate() {
            assert_eq!(all.h(i), b.h[i]);
            assert_eq!(all.amplitude(i), Some(x));
        }
        assert_eq!(all.indices(), 0..41);
        // The file is unnamed: the folder holds nothing.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
