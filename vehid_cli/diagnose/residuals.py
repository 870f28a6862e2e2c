"""Residual analysis of a fitted full-car model: is what is left noise, or missing physics?

* power: chi² per sample, the noise-weighted residual power over the noise power the data implies
  (the task's sigma: Eq. 15 from noise.level, or estimated from the data when noise.level is 0);
* whiteness per channel: normalised autocorrelation up to a lag, the ±1.96/sqrt(n) band, and the
  Ljung-Box portmanteau Q = n (n + 2) sum_k rho_k² / (n - k), chi²(lags) under white noise;
* cross-correlation of each residual channel with each road velocity (the input), against the same band;
* the spectral residual: Welch power spectral density of each weighted residual channel, scaled so that
  white noise of the implied sigma lies at 1 (a peak or a low-frequency hump is structure the model misses);
* the fingerprint: each corner's residual binned against that corner's suspension velocity and deflection
  (deflection d = G q_body - wheel, from the fitted model's states), where a missing strut effect shows
  as a systematic shape (an odd step: friction; a kink at v = 0: asymmetric damping; d³: a progressive spring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..identify.corrections import corrected, is_sensor_unknown
from ..models.sensors import UNIT
from .tails import chi2_sf

BAND_Z = 1.959963984540054  # two-sided 95 %
WELCH_SEGMENT_S = 1.0  # residual_spectrum's Welch segment [s] (shorter for records under 8 s: 8 segments)
SPECTRUM_BATCH_BYTES = 4 * 2**20  # `spectrum` takes the channels' segments (twice the residual) at once below this,
# one channel at a time above (a long record's: 18 MiB of segments, windows and transforms at 60 s, 8 channels, 1 kHz,
# 2 MiB per channel; the same PSD to round-off, NumPy reducing a lone column in another order: issue 26)


@dataclass(frozen=True)
class Whiteness:
    """Autocorrelation and Ljung-Box test of one residual sequence."""

    acf: NDArray  # (lags + 1,) rho_0 = 1 .. rho_lags
    band: float  # 1.96 / sqrt(n)
    outside: float  # fraction of lags 1..L with |rho_k| above the band (about 5 % for white noise)
    q: float  # Ljung-Box statistic
    p_value: float  # under chi²(lags)
    lags: int


def autocorrelation(x: NDArray, lags: int) -> NDArray:
    """Normalised (biased) autocorrelation rho_0..rho_lags of a 1-D sequence, mean removed."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    den = float(np.dot(x, x))
    if den == 0.0:
        return np.r_[1.0, np.zeros(lags)]
    return np.array([1.0] + [float(np.dot(x[: n - k], x[k:])) / den for k in range(1, lags + 1)])


def ljung_box(x: NDArray, lags: int = 20) -> Whiteness:
    """Whiteness of x: its autocorrelation, the 95 % band and the Ljung-Box Q with its p-value."""
    x = np.asarray(x, dtype=float).ravel()
    n = x.size
    lags = int(max(1, min(lags, n // 4)))
    acf = autocorrelation(x, lags)
    k = np.arange(1, lags + 1)
    q = float(n * (n + 2) * np.sum(acf[1:] ** 2 / (n - k)))
    band = BAND_Z / np.sqrt(n)
    return Whiteness(
        acf=acf,
        band=float(band),
        outside=float(np.mean(np.abs(acf[1:]) > band)),
        q=q,
        p_value=float(chi2_sf(q, lags)),
        lags=lags,
    )


def cross_correlation(x: NDArray, u: NDArray, lags: int) -> NDArray:
    """Normalised cross-correlation r_xu(k) = sum x[t+k] u[t] / (|x| |u|), k = 0..lags (x after u)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    u = np.asarray(u, dtype=float) - np.mean(u)
    den = float(np.linalg.norm(x) * np.linalg.norm(u))
    n = x.size
    if den == 0.0:
        return np.zeros(lags + 1)
    return np.array([float(np.dot(x[k:], u[: n - k])) / den for k in range(lags + 1)])


@dataclass(frozen=True)
class Binned:
    """Mean weighted residual of one corner in bins of one of its strut variables."""

    variable: str  # "velocity" [m/s], "deflection" or "displacement" [m]
    centres: NDArray  # (bins,)
    mean: NDArray  # (bins,) mean residual (units of noise sigma)
    count: NDArray  # (bins,)

    @property
    def z(self) -> NDArray:
        """Each bin's mean over its standard error under white unit noise (|z| >> 2: a systematic shape)."""
        return self.mean * np.sqrt(np.maximum(self.count, 1))


def bin_residual(variable: NDArray, residual: NDArray, name: str, bins: int = 12) -> Binned:
    """Residual averaged in quantile bins of `variable` (equal counts: robust to long tails at rest)."""
    edges = np.unique(np.quantile(variable, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, variable, side="right") - 1, 0, edges.size - 2)
    nb = edges.size - 1
    count = np.bincount(idx, minlength=nb).astype(float)
    total = np.bincount(idx, weights=residual, minlength=nb)
    centre = np.bincount(idx, weights=variable, minlength=nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        return Binned(name, centre / count, total / count, count.astype(int))


@dataclass(frozen=True)
class ResidualAnalysis:
    """Everything the residual of one fit on one run says (channels: the layout's, acc then disp, as the objective
    orders them; the paper's acc1..4 then disp1..4)."""

    channels: tuple[str, ...]
    residual: NDArray  # (n, channels) weighted residual (data - model) / sigma; NaN where a channel has no sample
    chi2_per_sample: float
    chi2_channel: NDArray  # (channels,)
    whiteness: tuple[Whiteness, ...]  # per channel
    road_xcorr_max: NDArray  # (channels, 4) largest |cross-correlation| with each road velocity over lags
    band: float
    fingerprint: tuple[tuple[Binned, Binned], ...]  # per corner: (velocity, deflection), acc residual of that corner
    freq: NDArray | None = None  # (nf,) [Hz]
    psd: NDArray | None = None  # (channels, nf) residual PSD over the white level of the implied noise
    dt: float | None = None  # sampling step [s]
    measured: NDArray | None = None  # (n, channels) the data as the fit saw them, SI units; NaN where no sample
    sigma: NDArray | None = None  # (channels,) the noise sigma of each channel [its unit]
    units: tuple[str, ...] = ()  # each channel's SI unit

    @property
    def fitted(self) -> NDArray | None:
        """(n, channels) the model at the fit, as the data see it (a profiled offset included): measured - residual
        x sigma; None when the data were not kept."""
        if self.measured is None or self.sigma is None:
            return None
        return self.measured - self.residual * self.sigma

    def summary(self) -> dict:
        """Plain numbers for JSON."""
        return {
            "chi2_per_sample": self.chi2_per_sample,
            "chi2_per_channel": dict(zip(self.channels, map(float, self.chi2_channel), strict=True)),
            "ljung_box_p": dict(zip(self.channels, (w.p_value for w in self.whiteness), strict=True)),
            "acf_outside_band": dict(zip(self.channels, (w.outside for w in self.whiteness), strict=True)),
            "road_xcorr_max": float(np.max(self.road_xcorr_max)),
            "band": self.band,
            "spectrum_peak": None if self.psd is None else float(np.nanmax(self.psd)),
            "spectrum_peak_hz": None
            if self.psd is None
            else float(self.freq[np.nanargmax(np.nanmax(self.psd, axis=0))]),
            "fingerprint_max_z": [
                {"velocity": float(np.nanmax(np.abs(v.z))), "deflection": float(np.nanmax(np.abs(d.z)))}
                for v, d in self.fingerprint
            ],
        }


def welch(x: NDArray, fs: float, nperseg: int, axis: int = -1) -> tuple[NDArray, NDArray]:
    """Welch's one-sided power spectral density of x along `axis` (frequencies [Hz], PSD [unit²/Hz]): segments of
    `nperseg` samples (at most the signal's length) overlapping by half, each less its mean and under a periodic Hann
    window, their periodograms averaged. scipy.signal.welch's defaults, to rounding (tests/test_tails.py), without
    importing scipy.signal: it imports scipy.stats, about 0.5 s of a 3 s diagnosis's start-up on the 2-core VM."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
    nperseg = min(int(nperseg), x.shape[-1])
    step = nperseg - nperseg // 2
    win = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(nperseg) / nperseg)
    segments = np.lib.stride_tricks.sliding_window_view(x, nperseg, axis=-1)[..., ::step, :]
    spec = np.fft.rfft((segments - segments.mean(axis=-1, keepdims=True)) * win, axis=-1)
    p = (spec.real**2 + spec.imag**2) / (fs * np.sum(win**2))
    p[..., 1 : (-1 if nperseg % 2 == 0 else None)] *= 2.0  # one-sided: every bin but DC (and Nyquist) twice
    return np.fft.rfftfreq(nperseg, 1.0 / fs), np.moveaxis(p.mean(axis=-2), -1, axis)


def spectrum(residual: NDArray, dt: float) -> tuple[NDArray, NDArray]:
    """Welch PSD of each column of a weighted residual (n, channels), over the white level 2 dt of unit noise.

    A column that is NaN between its own samples (a slow channel on a faster grid) is taken at its own samples
    and rate, and its PSD interpolated onto the grid's frequencies (NaN above its own Nyquist frequency)."""
    n = residual.shape[0]
    clean = np.nan_to_num(residual)
    if 2 * clean.nbytes <= SPECTRUM_BATCH_BYTES:
        f, p = welch(clean, 1.0 / dt, min(256, n), axis=0)
        out = (p / (2.0 * dt)).T
    else:  # a long record's: one channel's segments at a time (SPECTRUM_BATCH_BYTES)
        parts = [welch(clean[:, j], 1.0 / dt, min(256, n)) for j in range(clean.shape[1])]
        f = parts[0][0]
        out = np.stack([p / (2.0 * dt) for _, p in parts])
    del clean
    for j in np.flatnonzero(~np.all(np.isfinite(residual), axis=0)):
        at = np.flatnonzero(np.isfinite(residual[:, j]))
        if at.size < 2:
            out[j] = np.nan
            continue
        dt_j = dt * float(np.median(np.diff(at)))
        fj, pj = welch(residual[at, j], 1.0 / dt_j, min(256, at.size))
        out[j] = np.where(f <= fj[-1], np.interp(f, fj, pj / (2.0 * dt_j)), np.nan)
    return f, out


def residual_spectrum(residual: NDArray, fs: float) -> tuple[NDArray, NDArray]:
    """Welch's one-sided amplitude spectral density of a residual sampled at `fs` [Hz]: (freq [Hz], ASD [unit/√Hz])."""
    nper = int(min(residual.size, max(16, min(WELCH_SEGMENT_S * fs, residual.size // 8))))
    freq, psd = welch(residual, fs, nper)
    return freq, np.sqrt(psd)


def fingerprint_channels(layout, p: dict[str, float], names: tuple[str, ...]) -> tuple[int, ...]:
    """For corners 1..4, the channel (index into `names`, channels of `layout`) whose residual is binned against
    that corner's strut motion: the body accelerometer nearest the corner (the paper's acc1..acc4 above them), else
    the corner's deflection sensor, else its wheel accelerometer, else the nearest body displacement sensor, else
    its wheel displacement, else channel 0. `p`: the car's a1, a2, b1, b2 [m]."""
    kinds = {s.name: s for s in layout.sensors}
    xy = layout.body_xy(p)
    corner_xy = {1: (p["a1"], p["b1"]), 2: (p["a1"], -p["b2"]), 3: (-p["a2"], -p["b2"]), 4: (-p["a2"], p["b1"])}
    out = []
    for c in range(1, 5):
        cx, cy = corner_xy[c]

        def nearest(kind: str, cx=cx, cy=cy) -> str | None:
            found = [n for n in names if kinds[n].kind == kind]
            return min(found, key=lambda n: math.hypot(xy[n][0] - cx, xy[n][1] - cy), default=None)

        def at_corner(kind: str, c=c) -> str | None:
            return next((n for n in names if kinds[n].kind == kind and kinds[n].corner == c), None)

        choice = (
            nearest("body_acc") or at_corner("deflection") or at_corner("wheel_acc") or nearest("body_disp")
            or at_corner("wheel_disp")
        )  # fmt: skip
        out.append(names.index(choice) if choice is not None else 0)
    return tuple(out)


def analyse(
    task, reference: dict[str, NDArray], names, x: NDArray, lags: int = 20, bins: int = 12,
    measured: NDArray | None = None,
):  # fmt: skip
    """Residual analysis of the car `names` = x on the task's experiment (one run) against `reference`.

    The residual is the task's objective's (offsets profiled out when they are identified), per channel of the
    layout; a channel slower than the grid is analysed at its own samples (NaN elsewhere in `residual`). `measured`:
    an earlier analysis's of the same run and reference (the data as laid out here), shared rather than made again
    (a long record's is several MB)."""
    exp = task.experiment
    objective = task.objective(reference)
    every = {n: np.asarray(v, dtype=float) for n, v in zip(names, x, strict=True)}
    values = {n: v for n, v in every.items() if not is_sensor_unknown(n)}  # the car's; the chain's corrected below
    with np.errstate(all="ignore"):
        resp = exp.simulate(values)
    sim = exp.read(resp)
    G = exp.matrices(values).G
    defl = resp.q[:, :3] @ G.T - resp.q[:, 3:]
    vel = resp.qd[:, :3] @ G.T - resp.qd[:, 3:]
    del resp  # the car's whole trajectories (a long record's: 20 MB) are not needed past here
    if task.corrections:
        batch = corrected(task.corrections, {f: v[None] for f, v in sim.items()}, every)
        sim = {f: v[0] for f, v in batch.items()}
    parts, channels, data, units = [], [], [], []
    for family in reference:
        r = objective.error(family, sim[family]) / task.sigma[family]
        if task.observed is not None:
            r = np.where(task.observed[family], r, np.nan)
        parts.append(r)
        if measured is None:
            y = np.array(reference[family], dtype=float)
            data.append(y if task.observed is None else np.where(task.observed[family], y, np.nan))
        channels += list(exp.layout.names(family))
        units += [UNIT[family]] * r.shape[1]
    residual = np.concatenate(parts, axis=1)
    del parts, sim, r  # copies beside the residual (a long record's: several MB each)
    n = residual.shape[0]
    full = bool(np.all(np.isfinite(residual)))
    own = [np.isfinite(residual[:, j]) for j in range(residual.shape[1])]
    white = tuple(ljung_box(residual[ok, j], lags) for j, ok in enumerate(own))
    road_v = np.gradient(exp.road, exp.dt, axis=0)
    xc = np.array(
        [[np.max(np.abs(cross_correlation(residual[ok, j], road_v[ok, i], lags))) for i in range(4)]
         for j, ok in enumerate(own)]
    )  # fmt: skip
    p = {k: float(np.asarray(v)) for k, v in exp.parameters(values).items()}
    picks = fingerprint_channels(exp.layout, p, tuple(channels))
    fingerprint = tuple(
        (
            bin_residual(vel[own[j], i], residual[own[j], j], "velocity", bins),
            bin_residual(defl[own[j], i], residual[own[j], j], "deflection", bins),
        )
        for i, j in enumerate(picks)
    )
    del defl, vel
    square = residual**2
    chi2_per_sample = float(np.mean(square) if full else np.nanmean(square))
    chi2_channel = np.mean(square, axis=0) if full else np.nanmean(square, axis=0)
    del square
    measured = np.concatenate(data, axis=1) if measured is None else measured
    del data  # before the spectrum's segments: a long record's copies are several MB each
    return ResidualAnalysis(
        channels=tuple(channels),
        residual=residual,
        chi2_per_sample=chi2_per_sample,
        chi2_channel=chi2_channel,
        whiteness=white,
        road_xcorr_max=xc,
        band=float(BAND_Z / np.sqrt(n)),
        fingerprint=fingerprint,
        freq=(spec := spectrum(residual, exp.dt))[0],
        psd=spec[1],
        dt=float(exp.dt),
        measured=measured,
        sigma=np.concatenate([np.asarray(task.sigma[f], dtype=float) for f in reference]),
        units=tuple(units),
    )


def analyse_bench(history, model_force: NDArray, sigma: float, lags: int = 20, bins: int = 12) -> ResidualAnalysis:
    """Residual analysis of a damper on a bench: (measured - model) / sigma, its whiteness, its correlation
    with the velocity input, its spectrum and its fingerprint against the stroke velocity and displacement."""
    residual = ((np.asarray(history.force) - np.asarray(model_force)) / sigma)[:, None]
    n = residual.shape[0]
    xc = np.array([[np.max(np.abs(cross_correlation(residual[:, 0], history.v, lags)))]])
    f, psd = spectrum(residual, history.dt)
    return ResidualAnalysis(
        channels=("force",),
        residual=residual,
        chi2_per_sample=float(np.mean(residual**2)),
        chi2_channel=np.mean(residual**2, axis=0),
        whiteness=(ljung_box(residual[:, 0], lags),),
        road_xcorr_max=xc,
        band=float(BAND_Z / np.sqrt(n)),
        fingerprint=(
            (
                bin_residual(np.asarray(history.v), residual[:, 0], "velocity", bins),
                bin_residual(np.asarray(history.x), residual[:, 0], "displacement", bins),
            ),
        ),
        freq=f,
        psd=psd,
        dt=float(history.dt),
        measured=np.asarray(history.force, dtype=float)[:, None],
        sigma=np.array([sigma], dtype=float),
        units=("N",),
    )
