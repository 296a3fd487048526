"""Seeds for the fuzz targets log_mat, log_mat_v73, log_hdf5 and log_tdms,
written by the libraries labs' own tools use (scipy for level-5 MAT-files;
h5py and hdf5storage, as MATLAB lays out v7.3 files; npTDMS), not by
servoid, so the readers are seeded with files they did not write. Run from
the repository root:

    pip install scipy h5py hdf5storage npTDMS
    python3 fuzz/seeds/make_array_seeds.py

Each holds 256 samples at 1 kHz of a command u (mm), a displacement x (mm)
and a force f (N), which the targets' plans read (fuzz/src/targets.rs).
"""

import numpy as np
import h5py
import hdf5storage
from nptdms import TdmsWriter, ChannelObject, GroupObject

n = 256
t = np.arange(n) / 1000.0
u = 2.0 * np.sin(2 * np.pi * 37.0 * t)
x = 1.8 * np.sin(2 * np.pi * 37.0 * t - 0.3)
f = 150.0 * np.sin(2 * np.pi * 37.0 * t - 0.1)

# MAT v7.3 as MATLAB writes it: `t`, `u` column vectors, a struct `log`
# holding `x`, and a 256 x 3 table [u x f] (the only 2-D variable).
hdf5storage.savemat(
    "fuzz/corpus/log_mat_v73/vectors.mat",
    {
        "t": t.reshape(-1, 1),
        "u": u.reshape(-1, 1),
        "log": {"x": x.reshape(-1, 1)},
        "table": np.column_stack([u, x, f]),
    },
    format="7.3",
    truncate_existing=True,
    matlab_compatible=True,
    store_python_metadata=False,
)

# Plain HDF5 as h5py writes it: 1-D datasets, one inside a group, and a
# 256 x 3 row-major table, chunked and deflated.
with h5py.File("fuzz/corpus/log_hdf5/datasets.h5", "w") as h:
    h["t"] = t
    h["u"] = u
    h["u"].attrs["units"] = "mm"
    h.create_dataset("run/x", data=x, chunks=(16,), compression="gzip", shuffle=True)
    h["run/x"].attrs["units"] = "mm"
    h["table"] = np.column_stack([u, x, f])

# TDMS as NI's libraries write it: group `g`, waveform channels with their
# interval and units.
with TdmsWriter("fuzz/corpus/log_tdms/waveforms.tdms") as w:
    props = lambda unit: {"wf_increment": 1e-3, "wf_start_offset": 0.0, "unit_string": unit}
    w.write_segment(
        [
            GroupObject("g"),
            ChannelObject("g", "u", u, properties=props("mm")),
            ChannelObject("g", "x", x, properties=props("mm")),
            ChannelObject("g", "f", f, properties=props("N")),
        ]
    )

# What labs' files hold beside the channels: HDF5 (h5py's default,
# old-style groups) with soft links at the root and in a group, one
# dangling, text, boolean and complex datasets, and a second group.
with h5py.File("fuzz/corpus/log_hdf5/links_and_text.h5", "w") as h:
    h["t"] = t
    h["u"] = u
    h.create_dataset("run/x", data=x)
    h["table"] = np.column_stack([u, x, f])
    h["u_alias"] = h5py.SoftLink("/u")
    h["gone"] = h5py.SoftLink("/nothing")
    h["run/latest"] = h5py.SoftLink("/run/x")
    h["note"] = np.array(["operator: A", "specimen: k1"], dtype=h5py.string_dtype())
    h["valid"] = u > 0
    h["phasor"] = (u + 1j * x).astype(np.complex128)
    h.create_dataset("other/x", data=x)

# MAT v7.3 with MATLAB text beside the channels.
hdf5storage.savemat(
    "fuzz/corpus/log_mat_v73/with_text.mat",
    {
        "t": t.reshape(-1, 1),
        "u": u.reshape(-1, 1),
        "log": {"x": x.reshape(-1, 1), "operator": "A. N. Other"},
        "table": np.column_stack([u, x, f]),
        "note": "run k1, 4 mm chirp",
    },
    format="7.3",
    truncate_existing=True,
    matlab_compatible=True,
    store_python_metadata=False,
)

# TDMS as a logger appends it: the channels in four segments of 64
# samples, and a second group.
with TdmsWriter("fuzz/corpus/log_tdms/segments.tdms") as w:
    props = lambda unit: {"wf_increment": 1e-3, "wf_start_offset": 0.0, "unit_string": unit}
    for k in range(4):
        s = slice(64 * k, 64 * (k + 1))
        objects = [
            GroupObject("g"),
            ChannelObject("g", "u", u[s], properties=props("mm")),
            ChannelObject("g", "x", x[s], properties=props("mm")),
            ChannelObject("g", "f", f[s], properties=props("N")),
        ]
        if k == 0:
            objects += [GroupObject("h"), ChannelObject("h", "temperature", 20.0 + 0.01 * t)]
        w.write_segment(objects)

# TDMS with a string channel and an integer channel among the numeric
# ones, in two segments, the second repeating only the string channel's
# index (npTDMS writes the others' as "same as before").
with TdmsWriter("fuzz/corpus/log_tdms/strings.tdms") as w:
    notes = np.array([f"s{i}" for i in range(len(t))])
    for k in range(2):
        s = slice(128 * k, 128 * (k + 1))
        w.write_segment(
            [
                GroupObject("g"),
                ChannelObject("g", "note", notes[s]),
                ChannelObject("g", "u", u[s], properties={"wf_increment": 1e-3}),
                ChannelObject("g", "x", x[s]),
                ChannelObject("g", "f", (1000 * f[s]).astype(np.int32)),
            ]
        )

# MAT level 5 as MATLAB's default -v7 saves it (compressed): the signals
# as variables and a table [u x f] beside text, a cell array and a struct, which the reader
# passes over and names.
import scipy.io

scipy.io.savemat(
    "fuzz/corpus/log_mat/with_text.mat",
    {
        "t": t.reshape(-1, 1),
        "u": u.reshape(-1, 1),
        "data": np.column_stack([u, x, f]),
        "note": "run k1, 4 mm chirp",
        "cells": np.array([["k1"], ["chirp"]], dtype=object),
        "meta": {"rate_hz": 1000.0, "unit": "mm"},
    },
    do_compression=True,
)
