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

# New-style groups (h5py's libver="latest"), whose links are link
# messages: the displacement named as a soft link, and as an external
# link to another file.
for name, link in [
    ("log-hdf5-new-style-soft-link", h5py.SoftLink("/x")),
    ("log-hdf5-external-link", h5py.ExternalLink("other.h5", "/x")),
]:
    with h5py.File(case(name) + "a.h5", "w", libver="latest") as h:
        h["t"], h["u"], h["x"] = t, u, x
        h["x_link"] = link

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

# Files of another kind than their name says, as labs meet them: a MATLAB
# level-4 file (scipy writes `save -v4`'s layout), Octave's default text
# format, a level-5 MAT-file named .h5, a v7.3 struct array whose field is
# the displacement. Each is refused before its samples are read, so 200
# samples keep the files small.
import scipy.io

t, u, x = t[:200], u[:200], x[:200]
columns = {"t": t.reshape(-1, 1), "u": u.reshape(-1, 1), "x": x.reshape(-1, 1)}
scipy.io.savemat(case("log-mat-level4") + "a.mat", columns, format="4")
scipy.io.savemat(case("log-h5-is-mat-level5") + "a.h5", columns)
with open(case("log-mat-octave-text") + "a.mat", "w") as f:
    f.write("# Created by Octave 8.4.0, Sat Nov 28 10:00:00 2026 UTC <lab@rig>\n")
    for n, v in [("t", t), ("u", u), ("x", x)]:
        f.write(f"# name: {n}\n# type: matrix\n# rows: {len(v)}\n# columns: 1\n")
        f.writelines(f" {a!r}\n" for a in v)
        f.write("\n\n")
runs = np.zeros((2, 1), dtype=[("x", object)])
runs[0, 0]["x"], runs[1, 0]["x"] = x.reshape(-1, 1), x.reshape(-1, 1)
hdf5storage.savemat(
    case("log-mat-v73-struct-array") + "a.mat",
    {"t": t.reshape(-1, 1), "u": u.reshape(-1, 1), "log": runs},
    format="7.3",
    matlab_compatible=True,
    store_python_metadata=False,
    truncate_existing=True,
)

# A level-5 MAT-file (compressed, as MATLAB's default -v7 saves) whose
# displacement is text, beside a cell array.
scipy.io.savemat(
    case("log-mat-char") + "a.mat",
    {
        "t": t.reshape(-1, 1),
        "u": u.reshape(-1, 1),
        "x": "displacement in mm",
        "notes": np.array([["run k1"], ["4 mm chirp"]], dtype=object),
    },
    do_compression=True,
)
