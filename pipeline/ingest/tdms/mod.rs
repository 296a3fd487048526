//! NI TDMS logs (LabVIEW and NI DAQ software): each channel a variable named
//! `Group/Channel`, a vector of its samples, found as in every array format
//! (`arrays`); a bare channel name finds it where one group holds it. Where
//! the plan asks the log for its time base, a waveform channel's
//! `wf_increment` (the sample interval, s) gives the rate; a channel's
//! `unit_string` is checked against the manifest's unit. Numbers of any of
//! TDMS's integer and float types are widened to f64; string, boolean,
//! timestamp and complex channels are passed over and named when a plan asks
//! for one; DAQmx raw data are refused with a message. Where the values lie
//! is `layout`'s walk over the segments.

mod layout;

use crate::warning::Warning;
use std::path::Path;

use super::arrays::{self, Arrays};
use super::plan::LogPlan;
use super::{FormatProblem, IngestError, MatVariable, Raw, RawTime};
use layout::Layout;

/// Read a TDMS log as `plan` describes it.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &[u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    arrays::read(path, &open(path, bytes)?, plan)
}

/// A TDMS log's channels with their units, and the rate its waveforms
/// state.
pub(super) fn columns(
    path: &Path,
    bytes: &[u8],
) -> Result<(Vec<super::LogColumn>, Option<f64>), IngestError> {
    let t = open(path, bytes)?;
    let rate = match t.own_time(path) {
        Ok(RawTime::Rate { hz, .. }) if hz.is_finite() && hz > 0.0 => Some(hz),
        _ => None,
    };
    Ok((arrays::columns(&t), rate))
}

fn open<'p, 'b>(path: &'p Path, bytes: &'b [u8]) -> Result<Tdms<'p, 'b>, IngestError> {
    if !bytes.starts_with(b"TDSm")
        && let Some(problem) = super::other_kind(bytes, "a TDMS file")
    {
        return Err(IngestError::format(path, problem));
    }
    let layout = layout::layout(bytes).map_err(|why| unreadable(path, why))?;
    if layout.channels.is_empty() {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "no channels".into(),
        });
    }
    // A recording cut short before its first whole chunk holds nothing to
    // read: the cut is the file's problem, not empty channels.
    if let Some(d) = &layout.dropped
        && layout.channels.iter().all(|c| c.len == 0)
    {
        return Err(unreadable(path, d.clone()));
    }
    let mut variables = Vec::new();
    let mut unusable = Vec::new();
    let mut numeric = Vec::new();
    for (i, ch) in layout.channels.iter().enumerate() {
        let name = format!("{}/{}", ch.group, ch.name);
        match ch.dtype.and_then(layout::not_numeric) {
            Some(what) => unusable.push(arrays::Unusable { name, what }),
            None => {
                variables.push(MatVariable {
                    name,
                    size: vec![ch.len, 1],
                });
                numeric.push(i);
            }
        }
    }
    Ok(Tdms {
        path,
        bytes,
        layout,
        variables,
        numeric,
        unusable,
    })
}

fn unreadable(path: &Path, why: String) -> IngestError {
    IngestError::format(path, FormatProblem::TdmsUnreadable { why })
}

struct Tdms<'p, 'b> {
    path: &'p Path,
    bytes: &'b [u8],
    layout: Layout,
    /// The numeric channels (and channels without values) as variables.
    variables: Vec<MatVariable>,
    /// Each variable's channel in `layout`.
    numeric: Vec<usize>,
    unusable: Vec<arrays::Unusable>,
}

impl Tdms<'_, '_> {
    fn channel(&self, name: &str) -> &layout::Channel {
        let i = self
            .variables
            .iter()
            .position(|v| v.name == name)
            .expect("a listed variable");
        &self.layout.channels[self.numeric[i]]
    }
}

impl Arrays for Tdms<'_, '_> {
    fn variables(&self) -> &[MatVariable] {
        &self.variables
    }

    fn values(&self, name: &str, _channel: &'static str) -> Result<Vec<f64>, IngestError> {
        let ch = self.channel(name);
        let Some(dtype) = ch.dtype else {
            return Ok(Vec::new());
        };
        let mut out = Vec::with_capacity(ch.len);
        for p in &ch.pieces {
            for i in 0..p.count {
                let v = layout::value(self.bytes, dtype, p, i).ok_or_else(|| {
                    unreadable(
                        self.path,
                        format!("channel `{name}`'s values run past the end of the file"),
                    )
                })?;
                out.push(v);
            }
        }
        Ok(out)
    }

    /// The rate from the first waveform channel's `wf_increment`: TDMS
    /// waveforms carry their sample interval, not their times.
    fn own_time(&self, path: &Path) -> Result<RawTime, IngestError> {
        match self.layout.channels.iter().find_map(|c| c.increment) {
            // A zero or negative interval becomes a rate the log's checks
            // refuse, naming where it came from.
            Some(dt) => Ok(RawTime::Rate {
                hz: 1.0 / dt,
                from: "the TDMS channel's wf_increment",
            }),
            None => Err(IngestError::format(
                path,
                FormatProblem::NoTimeBase {
                    variables: self.variables.clone(),
                },
            )),
        }
    }

    fn stated_unit(&self, name: &str) -> Option<String> {
        self.channel(name).unit.clone()
    }

    fn unusable(&self) -> &[arrays::Unusable] {
        &self.unusable
    }

    fn warnings(&self) -> Vec<Warning> {
        self.layout
            .dropped
            .iter()
            .map(|d| {
                Warning::new(
                    "the file ends inside a segment, which was dropped",
                    format!("{}: {d}", self.path.display()),
                )
            })
            .collect()
    }
}
