"""The bad-input corpus's array-format logs as labs' own tools write them
(h5py, hdf5storage as MATLAB lays out v7.3 files, npTDMS), from the
samples of `log-european-read/a.csv`. Run from the repository root:

    pip install h5py hdf5storage npTDMS
    python3 tests/bad/make_array_cases.py

Each case's manifest.toml and case.toml are written by hand; this script
writes only its log.
"""

import numpy as np
import h5py
import hdf5storage
from nptdms import TdmsWriter, ChannelObject, GroupObject

rows = [
    line.replace(",", ".").split(";")
    for line in open("tests/bad/log-european-read/a.csv").read().splitlines()[1:]
]
t, u, x = (np.array([float(r[k]) for r in rows]) for k in range(3))


def case(name):
    return f"tests/bad/{name}/"


# HDF5 from h5py with the default (earliest) file format, whose groups are
# old-style: datasets t, u, x and unused soft links beside them.
with h5py.File(case("log-hdf5-soft-link") + "a.h5", "w") as h:
    h["t"], h["u"], h["x"] = t, u, x
    h["x_alias"] = h5py.SoftLink("/x")
    h["gone"] = h5py.SoftLink("/nothing")
    g = h.create_group("raw")
    g["x"] = x
    g["latest"] = h5py.SoftLink("/raw/x")

# The same file, its displacement named as the soft link.
with h5py.File(case("log-hdf5-soft-link-asked") + "a.h5", "w") as h:
    h["t"], h["u"], h["x"] = t, u, x
    h["x_alias"] = h5py.SoftLink("/x")

# Non-numeric datasets where a channel is wanted: complex, boolean, text.
for name, value in [
    ("log-hdf5-complex", x.astype(np.complex128)),
    ("log-hdf5-bool", x > 0),
    ("log-hdf5-strings", np.array([f"{v:.5f}" for v in x], dtype=h5py.string_dtype())),
]:
    with h5py.File(case(name) + "a.h5", "w") as h:
        h["t"], h["u"], h["x"] = t, u, value

# MAT v7.3 with the displacement saved as text (a char array).
hdf5storage.savemat(
    case("log-mat-v73-char") + "a.mat",
    {"t": t.reshape(-1, 1), "u": u.reshape(-1, 1), "x": "displacement in mm"},
    format="7.3",
    matlab_compatible=True,
    store_python_metadata=False,
)

# TDMS: the channels in group `log`, which a manifest carried over from CSV
# logs names bare; and `x` in two groups, which a bare name cannot choose.
with TdmsWriter(case("log-tdms-bare-names") + "a.tdms") as w:
    w.write_segment(
        [GroupObject("log")] + [ChannelObject("log", n, v) for n, v in [("t", t), ("u", u), ("x", x)]]
    )
with TdmsWriter(case("log-tdms-bare-name-in-two-groups") + "a.tdms") as w:
    w.write_segment(
        [GroupObject("log")]
        + [ChannelObject("log", n, v) for n, v in [("t", t), ("u", u), ("x", x)]]
        + [GroupObject("raw"), ChannelObject("raw", "x", x)]
    )

# TDMS with a string channel beside the numeric ones (npTDMS and LabVIEW
# read it): unused, and then named as the displacement.
notes = np.array([f"sample {i}" for i in range(len(x))])
with TdmsWriter(case("log-tdms-string-channel") + "a.tdms") as w:
    w.write_segment(
        [GroupObject("log")]
        + [ChannelObject("log", n, v) for n, v in [("t", t), ("note", notes), ("u", u), ("x", x)]]
    )
with TdmsWriter(case("log-tdms-string-asked") + "a.tdms") as w:
    w.write_segment(
        [GroupObject("log")]
        + [ChannelObject("log", n, v) for n, v in [("t", t), ("u", u), ("x", notes)]]
    )

# TDMS as a logger appends it, four segments of 2000 samples, the file cut
# 1000 bytes before its end (a power loss during the fourth segment).
path = case("log-tdms-last-segment-cut") + "a.tdms"
with TdmsWriter(path) as w:
    for k in range(4):
        s = slice(2000 * k, 2000 * (k + 1))
        w.write_segment(
            [GroupObject("log")]
            + [ChannelObject("log", n, v[s]) for n, v in [("t", t), ("u", u), ("x", x)]]
        )
data = open(path, "rb").read()
open(path, "wb").write(data[:-1000])

# TDMS whose displacement's declared count is corrupt (3e9 values in a
# file of some 200 kB): the count is the u64 after the raw-data index's
# length, type and dimension words that follow the channel's path.
path = case("log-tdms-declared-count") + "a.tdms"
with TdmsWriter(path) as w:
    w.write_segment(
        [GroupObject("log")] + [ChannelObject("log", n, v) for n, v in [("t", t), ("u", u), ("x", x)]]
    )
data = bytearray(open(path, "rb").read())
name = b"/'log'/'x'"
at = data.index(len(name).to_bytes(4, "little") + name) + 4 + len(name) + 12
assert int.from_bytes(data[at : at + 8], "little") == len(x)
data[at : at + 8] = (3_000_000_000).to_bytes(8, "little")
open(path, "wb").write(bytes(data))
