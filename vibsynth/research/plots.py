"""Figures of the paper's analyses (matplotlib, Agg backend, imported lazily).

* :func:`plot_basis` -- M and V1..V8 over frequency (Fig. 6a);
* :func:`plot_spectrum` -- measured spectra vs their S1 (and S1:8, S2:8, M) reconstructions (Fig. 6c);
* :func:`plot_presets` -- presets on the balance axis, with the spectra at the axis' ends;
* :func:`plot_mds` -- the 2-D perceptual map of a ratings table (Fig. 7);
* :func:`plot_iso_curve` -- an iso-intensity curve from the lab's sines (Fig. 1b).

Every ``plot_*`` function writes a PNG (atomically) and returns its path; the matching
``*_figure`` function builds the :class:`matplotlib.figure.Figure` without saving it (to
show, restyle or inspect). Figures are made with matplotlib's object API, not pyplot, inside
a local :func:`matplotlib.rc_context`: no global matplotlib state (``rcParams``, backend,
pyplot's figure list) is changed. matplotlib is an optional dependency
(``pip install 'vibsynth[research]'``).
"""

from __future__ import annotations

import functools
import io
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vibsynth.dsp.basis import Basis, normalise_db
from vibsynth.errors import PresetError, VibsynthError
from vibsynth.research.dissim import MissingDependencyError

__all__ = [
    "plot_basis",
    "plot_spectrum",
    "plot_presets",
    "plot_mds",
    "basis_figure",
    "spectrum_figure",
    "presets_figure",
    "mds_figure",
    "plot_iso_curve",
    "iso_curve_figure",
]

_DPI = 120
_RC = {
    "font.size": 11,
    "axes.titlesize": 12,
    "axes.labelsize": 11,
    "legend.fontsize": 9,
    "xtick.labelsize": 10,
    "ytick.labelsize": 10,
    "axes.grid": True,
    "grid.alpha": 0.3,
}


def _matplotlib() -> Any:
    """The matplotlib module, or :class:`MissingDependencyError` saying how to install it."""
    try:
        import matplotlib
        import matplotlib.figure  # noqa: F401 - the Figure class used below
    except ImportError:
        raise MissingDependencyError("plotting needs matplotlib: pip install 'vibsynth[research]'") from None
    return matplotlib


def _new_figure(**kwargs: Any) -> Any:
    """A Figure not registered with pyplot (garbage-collected like any object)."""
    return _matplotlib().figure.Figure(**kwargs)


def _styled(build: Callable[..., Any]) -> Callable[..., Any]:
    """Run a figure builder inside a local style context (matplotlib's global rcParams stay untouched)."""

    @functools.wraps(build)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with _matplotlib().rc_context(_RC):
            return build(*args, **kwargs)

    return wrapper


def _save(fig: Any, path: str | os.PathLike[str]) -> Path:
    from vibsynth.formats.files import atomic_write_bytes

    buffer = io.BytesIO()
    with _matplotlib().rc_context(_RC):
        fig.savefig(buffer, format="png", dpi=_DPI, bbox_inches="tight")
    atomic_write_bytes(path, buffer.getvalue())
    return Path(path)


def _freq_axis(ax: Any, basis: Basis) -> None:
    ax.set_xscale("log")
    ax.set_xlim(basis.centres_hz[0] / 1.1, basis.centres_hz[-1] * 1.1)
    ax.set_xlabel("band centre frequency (Hz)")


def plot_basis(basis: Basis, path: str | os.PathLike[str]) -> Path:
    """M and the components V1..Vn (paper, Fig. 6a).

    Parameters
    ----------
    basis : Basis
    path : path-like
        PNG to write.
    """
    return _save(basis_figure(basis), path)


@_styled
def basis_figure(basis: Basis) -> Any:
    """The figure of :func:`plot_basis`: axes 0 is M, axes i the component Vi (line i's data).

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    k = basis.n_components
    fig = _new_figure(figsize=(7, 1.55 * (k + 1)))
    axes = fig.subplots(k + 1, 1, sharex=True)
    f = basis.centres_hz
    axes[0].plot(f, basis.mean_db, "k-o", ms=3)
    axes[0].set_ylabel("M (dB)")
    axes[0].set_title(f"Spectral basis {basis.id}: mean M and components (level-normalised dB spectra)")
    for i in range(k):
        ax = axes[i + 1]
        ax.axhline(0, color="0.6", lw=0.8)
        ax.plot(f, basis.components[i], "-o", ms=3, color="C0" if i == 0 else "C1")
        ax.set_ylabel(f"V{i + 1}")
        ax.text(
            0.99,
            0.85,
            f"{100 * basis.explained_variance_ratio[i]:.1f} % var.",
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize=9,
        )
    _freq_axis(axes[-1], basis)
    fig.text(0.005, 0.4, "component weight (dB per unit score)", rotation=90, fontsize=10)
    return fig


def plot_spectrum(
    spectra: Sequence[tuple[str, Any]],
    basis: Basis,
    path: str | os.PathLike[str],
    *,
    variants: bool = False,
) -> Path:
    """Measured level-normalised spectra vs their reconstructions (paper, Fig. 6c).

    Parameters
    ----------
    spectra : sequence of (label, band_db)
        ``band_db`` shape (n_bands,): measured 30-band spectra in dB.
    basis : Basis
    path : path-like
    variants : bool
        Also draw S2:8 and M (the paper's experiment-3 anchors); S1 and S1:8 are always drawn.
    """
    return _save(spectrum_figure(spectra, basis, variants=variants), path)


@_styled
def spectrum_figure(spectra: Sequence[tuple[str, Any]], basis: Basis, *, variants: bool = False) -> Any:
    """The figure of :func:`plot_spectrum`: one axes per recording, lines labelled as in its legend.

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    n = len(spectra)
    if n == 0:
        raise VibsynthError("plot spectrum needs at least one recording")
    fig = _new_figure(figsize=(7, 3.0 * n))
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)
    for ax, (label, band_db) in zip(axes[:, 0], spectra):
        measured = normalise_db(np.asarray(band_db, dtype=np.float64))
        scores = basis.scores(band_db)
        f = basis.centres_hz
        ax.plot(f, measured, "k-", lw=2.2, label="measured")
        ax.plot(
            f, basis.reconstruct(scores, components=slice(0, 1)), "C3--", lw=1.8, label=f"S1 (t1 = {scores[0]:+.1f})"
        )
        ax.plot(f, basis.reconstruct(scores, components=slice(0, None)), "C0:", lw=1.8, label="S1:8")
        if variants:
            ax.plot(f, basis.reconstruct(scores, components=slice(1, None)), "C2-.", lw=1.2, label="S2:8")
            ax.plot(f, basis.mean_db, color="0.5", lw=1.2, label="M")
        ax.set_ylabel("band power (dB, level-normalised)")
        ax.set_title(label)
        ax.legend(loc="best")
    _freq_axis(axes[-1, 0], basis)
    return fig


def plot_presets(presets: Sequence[tuple[str, float, float]], basis: Basis, path: str | os.PathLike[str]) -> Path:
    """Presets on the balance axis (marker size: intensity), above the spectra at balance -1, 0, +1.

    Parameters
    ----------
    presets : sequence of (name, balance, intensity)
    basis : Basis
    path : path-like
    """
    return _save(presets_figure(presets, basis), path)


@_styled
def presets_figure(presets: Sequence[tuple[str, float, float]], basis: Basis) -> Any:
    """The figure of :func:`plot_presets`: axes 0 the balance axis (one scatter), axes 1 the spectra.

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    if not presets:
        raise PresetError("no presets to plot")
    fig = _new_figure(figsize=(8, 6.5))
    ax, ax2 = fig.subplots(2, 1, gridspec_kw={"height_ratios": [1.2, 1]})
    names = [p[0] for p in presets]
    bal = np.array([p[1] for p in presets], dtype=np.float64)
    inten = np.array([p[2] for p in presets], dtype=np.float64)
    order = np.argsort(bal)
    y = np.arange(len(presets))
    ax.axvline(0, color="0.6", lw=0.8)
    ax.scatter(
        bal[order], y, s=30 + 170 * np.clip(inten[order], 0, 1), c=bal[order], cmap="coolwarm", edgecolors="k", zorder=3
    )
    for yi, i in zip(y, order):
        ax.annotate(names[i], (bal[i], yi), xytext=(8, 0), textcoords="offset points", va="center", fontsize=9)
    ax.set_yticks([])
    lim = max(1.2, float(np.abs(bal).max()) + 0.5)
    ax.set_xlim(-lim, lim)
    ax.set_xlabel("balance (knob units: 0 = M, +-1 = 98th/2nd percentile of t1; + = brighter)")
    ax.set_title("Presets on the balance axis (marker size = intensity knob 0..1)")
    for b, color in ((-1.0, "C0"), (0.0, "k"), (1.0, "C3")):
        ax2.plot(basis.centres_hz, basis.spectrum_for_balance(b), color=color, lw=1.8, label=f"balance {b:+g}")
    _freq_axis(ax2, basis)
    ax2.set_ylabel("band power (dB, level-normalised)")
    ax2.legend(loc="best")
    fig.tight_layout()
    return fig


def plot_mds(mds: Any, path: str | os.PathLike[str], *, title: str = "") -> Path:
    """Fig. 7-style perceptual map.

    Parameters
    ----------
    mds : vibsynth.research.dissim.MdsMap
        Rated positions (blue), the model's positions after Procrustes (red), errors
        (grey), and the projection of V1 (arrow) with the unit circle.
    path : path-like
    title : str
    """
    return _save(mds_figure(mds, title=title), path)


@_styled
def mds_figure(mds: Any, *, title: str = "") -> Any:
    """The figure of :func:`plot_mds` (one axes: rated and model scatters, error lines, V1 arrow).

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    fig = _new_figure(figsize=(7, 6.5))
    ax = fig.subplots()
    rated, pred = mds.rated, mds.predicted
    for a, b in zip(rated, pred):
        ax.plot([a[0], b[0]], [a[1], b[1]], color="0.6", lw=1, zorder=1)
    ax.scatter(rated[:, 0], rated[:, 1], c="C0", s=40, label="rated (MDS of mean ratings)", zorder=3)
    ax.scatter(pred[:, 0], pred[:, 1], c="C3", s=25, marker="s", label="model (MDS of D, Procrustes)", zorder=3)
    for name, p in zip(mds.names, rated):
        ax.annotate(name, p, xytext=(4, 4), textcoords="offset points", fontsize=8)
    scale = float(np.max(np.abs(np.concatenate([rated, pred])))) or 1.0
    r = mds.component_r[0]
    if np.all(np.isfinite(r)):
        ax.annotate(
            "", xy=(r[0] * scale, r[1] * scale), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="k", lw=1.8)
        )
        ax.text(r[0] * scale, r[1] * scale, f"  V1 (r = {r[0]:+.2f}, {r[1]:+.2f})", fontsize=9)
        theta = np.linspace(0, 2 * np.pi, 200)
        ax.plot(scale * np.cos(theta), scale * np.sin(theta), color="0.8", lw=0.8, ls="--")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("MDS dimension 1 (rating units)")
    ax.set_ylabel("MDS dimension 2 (rating units)")
    ax.set_title(title or f"Perceptual space (Procrustes RMS error {mds.procrustes_rms:.3f})")
    ax.legend(loc="best")
    return fig


def plot_iso_curve(curve: Any, path: str | os.PathLike[str], *, title: str = "") -> Path:
    """Fig. 1b-style iso-intensity curve.

    Parameters
    ----------
    curve : vibsynth.research.lab.iso.IsoCurve
        Drive (voltage) for equal intensity, dB re the reference sine: the mean with +-1 SD and
        each participant thin; in acceleration too when the curve has it (a measured response).
    path : path-like
    title : str
    """
    return _save(iso_curve_figure(curve, title=title), path)


@_styled
def iso_curve_figure(curve: Any, *, title: str = "") -> Any:
    """The figure of :func:`plot_iso_curve` (one axes, log frequency).

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    fig = _new_figure(figsize=(7, 4.5))
    ax = fig.subplots()
    f = curve.freqs_hz
    for row in curve.voltage_db:
        ax.plot(f, row, color="C3", lw=0.7, alpha=0.35)
    ax.plot(f, curve.mean_db, "o-", color="C3", lw=2, label=f"input voltage (mean of {len(curve.participants)})")
    if np.isfinite(curve.sd_db).any():
        ax.fill_between(f, curve.mean_db - curve.sd_db, curve.mean_db + curve.sd_db, color="C3", alpha=0.15)
    if curve.acceleration_db is not None:
        ax.plot(f, curve.acceleration_db, "s-", color="C0", lw=2, label="acceleration (measured response)")
    ax.axvline(curve.reference_hz, color="0.5", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"level for equal intensity (dB re the {curve.reference_hz:g} Hz reference)")
    ax.set_title(title or "Iso-intensity curve (direct intensity matching with sines)")
    ax.legend(loc="best")
    return fig
