#!/usr/bin/env python3
"""The work of `servoid run --figures none` on a campaign of CSV logs, in
numpy/scipy, as a reference for speed and for the numbers.

    python3 identify.py CAMPAIGN.toml [--json OUT.json] [--estimator etfe|h1]
                        [--window hann] [--simulator lsim|lfilter]

For each run of the campaign manifest (as `servoid simulate` writes it):
read the CSV log with polars and convert the channels to SI; estimate the
FRF command -> displacement; mask the bins by the band and the coherence
(scipy.signal.coherence, that is csd/welch, with the manifest's segment
settings); fit n0/(s^2 + d1 s + d0) times the command's zero-order hold
Z(jw) = exp(-jwT/2) sin(wT/2)/(wT/2) with scipy.optimize.least_squares;
the rig parameters from the no-specimen and spring runs by Eqs. 18-20;
then each validation run simulated by scipy.signal.lsim of the 4th-order
transfer function of the rig with its SDOF specimen, driven by the
measured command, with NRMSE and NAE (Eqs. 47-48).

The FRF estimator follows the manifest: with `estimator = "etfe"` (the
bundled default) the estimate is Y/U over the whole record, and the Welch
segments serve the coherence only; with "h1" it is Pyu/Puu from
scipy.signal.csd/welch. `--estimator h1` forces the Welch H1 on an ETFE
manifest, to see its bias on a sweep, and `--window` changes the segments'
window (the manifest's rectangular one suits the coherence, not an H1).

`--simulator lfilter` replaces lsim, whose zero-order-hold path steps the
state in a Python loop, by scipy.signal.lfilter of the same model
discretised with its hold (cont2discrete, "zoh"): the same response, in C.

Where it differs from servoid, on purpose (see docs/accuracy.md): the fit's weights
are |U(k)|^2 (white output noise) where servoid estimates the noise level
locally; no standard deviations, no force FRF or force validation, no
canonical-form checks, no per-window errors, no log checks or hashes.
"""

import argparse
import json
import sys
import time
import tomllib
from pathlib import Path

T_START = time.perf_counter()

import numpy as np  # noqa: E402
import polars as pl  # noqa: E402
from scipy import optimize, signal  # noqa: E402

T_IMPORTED = time.perf_counter()

TO_SI = {
    "m": 1.0,
    "cm": 1e-2,
    "mm": 1e-3,
    "in": 0.0254,
    "N": 1.0,
    "kN": 1e3,
    "lbf": 4.4482216152605,
    "s": 1.0,
    "ms": 1e-3,
}
SCIPY_WINDOW = {
    "rectangular": "boxcar",
    "hann": "hann",
    "hamming": "hamming",
    "blackman_harris": "blackmanharris",
}


class Timer:
    """Seconds spent per stage, summed over the runs."""

    def __init__(self):
        self.seconds = {}

    def add(self, stage, since):
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - since
        return now


def channel(channels, run, name):
    spec = dict(channels.get(name, {}))
    spec.update((run.get("channels") or {}).get(name, {}))
    return spec


def read_log(path, channels, run):
    """The log's time base and its command, displacement (m), in SI."""
    names = ("time", "command", "displacement")
    columns = [channel(channels, run, n)["column"] for n in names]
    df = pl.read_csv(path, columns=columns, schema_overrides={c: pl.Float64 for c in columns})

    def si(name):
        spec = channel(channels, run, name)
        raw = df[spec["column"]].to_numpy()
        scale, offset = spec.get("scale", 1.0), spec.get("offset", 0.0)
        return (raw * scale + offset) * TO_SI[spec["unit"]]

    t = si("time")
    fs = (len(t) - 1) / (t[-1] - t[0])
    return fs, si("command"), si("displacement")


def hold(f_hz, fs):
    """The D/A converter's zero-order hold, Z(jw) = exp(-jwT/2) sinc."""
    half = np.pi * f_hz / fs  # w T / 2
    return np.exp(-1j * half) * np.sinc(f_hz / fs)


def frf(u, y, fs, settings, estimator, window):
    """Bin frequencies, the estimate, the coherence and the fit weights."""
    nperseg = settings["segment_length"]
    noverlap = int(np.floor(settings.get("overlap", 0.5) * nperseg))
    window = SCIPY_WINDOW[window or settings.get("window", "hann")]
    detrend = {"mean": "constant", "linear": "linear", "none": False}[
        settings.get("detrend", "mean")
    ]
    welch = {
        "fs": fs,
        "window": window,
        "nperseg": nperseg,
        "noverlap": noverlap,
        "detrend": detrend,
    }
    f_w, coh = signal.coherence(u, y, **welch)
    if estimator == "etfe":
        if window != "boxcar":
            raise SystemExit("this script's ETFE takes a rectangular window only")
        if detrend == "constant":
            u, y = u - u.mean(), y - y.mean()
        elif detrend == "linear":
            u, y = signal.detrend(u), signal.detrend(y)
        uf, yf = np.fft.rfft(u), np.fft.rfft(y)
        f = np.fft.rfftfreq(len(u), 1.0 / fs)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = yf / uf
        coherence = np.interp(f, f_w, coh)
        weight = np.abs(uf) ** 2
    else:
        _, puu = signal.welch(u, **welch)
        _, pyu = signal.csd(u, y, **welch)
        f = f_w
        with np.errstate(divide="ignore", invalid="ignore"):
            h = pyu / puu
        coherence = coh
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = coh / (1.0 - coh) / np.abs(h) ** 2
    return f, h, coherence, weight


def fit_second_order(f, h, weight, fs, intersample):
    """n0 / (s^2 + d1 s + d0), the hold included: Levy's linear start,
    then least squares on the weighted complex error."""
    s = 2j * np.pi * f
    z = hold(f, fs) if intersample == "sample_and_hold" else np.ones_like(s)
    # Levy: z n0 - h s d1 - h d0 = h s^2, linear in (n0, d1, d0).
    a = np.stack([z, -h * s, -h], axis=1)
    b = h * s**2
    sw = np.sqrt(weight / weight.max())
    a_w = a * sw[:, None]
    b_w = b * sw
    start, *_ = np.linalg.lstsq(
        np.concatenate([a_w.real, a_w.imag]), np.concatenate([b_w.real, b_w.imag]), rcond=None
    )

    def residuals(p):
        n0, d1, d0 = p
        e = (z * n0 / (s**2 + d1 * s + d0) - h) * sw
        return np.concatenate([e.real, e.imag])

    sol = optimize.least_squares(
        residuals, start, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12
    )
    if not sol.success:
        raise RuntimeError(f"least_squares: {sol.message}")
    return sol.x


def rig_parameters(no_specimen, springs):
    """Eqs. 18-20: beta1 and R1 from the no-specimen fit, R2 and R3 per
    spring, a1b0, a2 and a3 per spring and averaged."""
    _n0, d1, d0 = no_specimen
    beta1, r1 = d1, d0
    per_spring = []
    for run_id, k, (n0k, _d1k, d0k) in springs:
        r2 = beta1 * k / (d0k / n0k - 1.0)
        r3 = (1.0 / n0k - 1.0 / r1) / k
        per_spring.append(
            {
                "run": run_id,
                "stiffness_n_per_m": k,
                "R2": r2,
                "R3": r3,
                "a1b0": 1.0 / r3,
                "a2": 1.0 / (r3 * r1),
                "a3": 1.0 / (r2 * r3),
            }
        )
    mean = {q: float(np.mean([p[q] for p in per_spring])) for q in ("a1b0", "a2", "a3")}
    return {"beta1": beta1, "R1": r1, **mean, "per_spring": per_spring}


def sdof_tf(rig, a1b0, m, c, k):
    """x1/u of the rig with an SDOF specimen (Eqs. 16-17)."""
    b1, a2, a3 = rig["beta1"], rig["a2"], rig["a3"]
    num = [a1b0]
    den = [
        m,
        a3 * m + c + b1 * m,
        k + a3 * c + a2 + b1 * a3 * m + b1 * c,
        a3 * k + b1 * k + b1 * a3 * c + b1 * a2,
        b1 * a3 * k + a1b0,
    ]
    return num, den


def validate(num, den, u, x_measured, fs, simulator):
    """The model from equilibrium at the first command sample, the command
    held between samples; NRMSE and NAE with the mean offset removed."""
    u0 = u[0]
    if simulator == "lsim":
        t = np.arange(len(u)) / fs
        _, x, _ = signal.lsim((num, den), u - u0, t, interp=False)
    else:
        numd, dend, _ = signal.cont2discrete((num, den), 1.0 / fs, method="zoh")
        x = signal.lfilter(np.ravel(numd), dend, u - u0)
    x = x + num[-1] / den[-1] * u0
    offset = np.mean(x_measured - x)
    xe = x_measured - offset
    peak = np.max(np.abs(xe))
    d = xe - x
    return {
        "nrmse_pct": float(np.sqrt(np.sum(d * d) / (len(d) - 1)) / peak * 100.0),
        "nae_pct": float(np.max(np.abs(d)) / peak * 100.0),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--json", type=Path, help="write the results here")
    ap.add_argument("--estimator", choices=["etfe", "h1"], help="override the manifest's")
    ap.add_argument("--window", choices=sorted(SCIPY_WINDOW), help="override the manifest's")
    ap.add_argument("--simulator", choices=["lsim", "lfilter"], default="lsim")
    args = ap.parse_args()

    timer = Timer()
    t = time.perf_counter()
    manifest = tomllib.loads(args.campaign.read_text())
    base = args.campaign.parent
    ident = manifest["identification"]
    band = ident["band_hz"]
    coherence_min = ident.get("coherence_min", 0.0)
    intersample = ident.get("command_intersample", "sample_and_hold")
    settings = ident["frf"]
    estimator = args.estimator or settings.get("estimator", "h1")
    if estimator not in ("etfe", "h1"):
        raise SystemExit(f"estimator {estimator} is not done here")
    channels = manifest["channels"]
    runs = manifest["runs"]

    fits = {}
    logs = {}
    for run in runs:
        t = time.perf_counter()
        fs, u, y = read_log(base / run["data"]["log"], channels, run)
        t = timer.add("read", t)
        if run["role"] == "validation":
            logs[run["id"]] = (fs, u, y)
            continue
        f, h, coh, weight = frf(u, y, fs, settings, estimator, args.window)
        t = timer.add("frf", t)
        mask = (
            (f >= band[0])
            & (f <= band[1])
            & (coh >= coherence_min)
            & (coh > 0)
            & np.isfinite(h)
            & (np.abs(h) > 0)
        )
        fits[run["id"]] = fit_second_order(f[mask], h[mask], weight[mask], fs, intersample)
        t = timer.add("fit", t)

    no_specimen = [r for r in runs if r["role"] == "no_specimen"]
    springs = [r for r in runs if r["role"] == "spring"]
    if len(no_specimen) != 1 or not springs:
        raise SystemExit("needs one no-specimen run and at least one spring run")
    p_ref = no_specimen[0].get("p_gain", 1.0)
    t = time.perf_counter()
    rig = rig_parameters(
        fits[no_specimen[0]["id"]],
        [(r["id"], r["specimen"]["stiffness_n_per_m"], fits[r["id"]]) for r in springs],
    )
    rig["p_gain"] = p_ref

    validation = {}
    for run in runs:
        if run["role"] != "validation":
            continue
        fs, u, y = logs.pop(run["id"])
        sp = run["specimen"]
        a1b0 = rig["a1b0"] * run.get("p_gain", 1.0) / p_ref
        num, den = sdof_tf(
            rig, a1b0, sp["mass_kg"], sp.get("damping_ns_per_m", 0.0), sp["stiffness_n_per_m"]
        )
        validation[run["id"]] = validate(num, den, u, y, fs, args.simulator)
        t = timer.add("validate", t)

    out = {
        "estimator": estimator,
        "window": args.window or settings.get("window", "hann"),
        "simulator": args.simulator,
        "rig": rig,
        "tf": {k: {"n0": v[0], "d1": v[1], "d0": v[2]} for k, v in fits.items()},
        "validation": validation,
        "seconds": {"import": T_IMPORTED - T_START, **timer.seconds},
    }
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    print(
        f"beta1 {rig['beta1']:.6g}  a1b0 {rig['a1b0']:.6g}  a2 {rig['a2']:.6g}  "
        f"a3 {rig['a3']:.6g}  R1 {rig['R1']:.6g}"
    )
    for k, v in validation.items():
        print(f"{k}: NRMSE {v['nrmse_pct']:.4f} %  NAE {v['nae_pct']:.4f} %")
    print(
        "seconds: "
        + ", ".join(f"{k} {v:.2f}" for k, v in out["seconds"].items())
        + f", total {time.perf_counter() - T_START:.2f}",
        file=sys.stderr,
    )


if __name__ == "__main__":
    main()
