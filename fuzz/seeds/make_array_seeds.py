"""Seeds for the fuzz targets log_mat_v73, log_hdf5 and log_tdms, written by
the libraries labs' own tools use (h5py and hdf5storage, as MATLAB lays out
v7.3 files; npTDMS), not by servoid, so the readers are seeded with files
they did not write. Run from the repository root:

    pip install h5py hdf5storage npTDMS
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
