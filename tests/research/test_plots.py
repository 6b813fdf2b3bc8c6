"""Plots: the data each figure draws, its labels, the PNG it writes, and no global matplotlib state."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib", reason="plots need matplotlib (vibsynth[research])")

from matplotlib.colors import to_rgb  # noqa: E402

from vibsynth.dsp.basis import normalise_db  # noqa: E402
from vibsynth.research import plots  # noqa: E402
from vibsynth.research.dissim import MissingDependencyError, mds_map, read_ratings  # noqa: E402

BLUE, ORANGE, RED = to_rgb("C0"), to_rgb("C1"), to_rgb("C3")


def read_png(path):
    """The PNG as an RGB float image, after checking it is a real, non-blank picture."""
    import matplotlib.image as mpimg

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    img = mpimg.imread(path)[..., :3]
    assert min(img.shape[:2]) >= 300
    grey = img.mean(axis=-1)
    assert grey.std() > 0.05  # not a blank canvas
    assert (grey < 0.5).mean() > 0.005  # some dark ink (lines, text)
    return img


def share_of(img, rgb, tol=0.06):
    """Fraction of pixels within ``tol`` of a colour (per channel)."""
    return float(np.all(np.abs(img - np.asarray(rgb)) < tol, axis=-1).mean())


def texts(legend):
    return [t.get_text() for t in legend.get_texts()]


def data_lines(ax):
    """Lines that plot data (not horizontal reference lines drawn with axhline)."""
    return [line for line in ax.get_lines() if len(np.atleast_1d(line.get_xdata())) > 2]


@pytest.fixture
def spectra(basis, rng):
    return [(f"s{i}", basis.mean_db + t * basis.v1 + rng.normal(0, 1, 30) - 40) for i, t in enumerate([-20, 25])]


PRESETS = [("rough", -0.8, 0.7), ("mid", 0.0, 0.5), ("bright", 1.1, 0.9)]


@pytest.fixture
def mds(tmp_path, rng):
    n = 8
    scores = rng.normal(size=(n, 8)) * [20, 8, 4, 3, 2, 1.5, 1, 0.8]
    for k in range(n):
        (tmp_path / f"s{k}.wav").write_bytes(b"")
    i, j = np.triu_indices(n)
    rows = [
        f"s{a}.wav,s{b}.wav,{0.1 + 0.01 * abs(scores[a, 0] - scores[b, 0]) + rng.normal(0, 0.02):.4f}"
        for a, b in zip(i, j)
    ]
    (tmp_path / "r.csv").write_text("file_a,file_b,rating\n" + "\n".join(rows) + "\n")
    table = read_ratings(tmp_path / "r.csv")
    order = [int(f.stem[1:]) for f in table.files]
    return mds_map(table, scores[order])


# ---------------------------------------------------------------------- what is drawn
def test_basis_figure_draws_m_and_every_component(basis):
    fig = plots.basis_figure(basis)
    k = basis.n_components
    axes = fig.axes
    assert len(axes) == k + 1
    (mean_line,) = data_lines(axes[0])
    np.testing.assert_array_equal(mean_line.get_xdata(), basis.centres_hz)
    np.testing.assert_array_equal(mean_line.get_ydata(), basis.mean_db)
    assert axes[0].get_ylabel() == "M (dB)" and basis.id in axes[0].get_title()
    for i in range(k):
        (line,) = data_lines(axes[i + 1])
        np.testing.assert_array_equal(line.get_ydata(), basis.components[i])
        assert to_rgb(line.get_color()) == (BLUE if i == 0 else ORANGE)
        assert axes[i + 1].get_ylabel() == f"V{i + 1}"
        notes = [t.get_text() for t in axes[i + 1].texts]
        assert notes == [f"{100 * basis.explained_variance_ratio[i]:.1f} % var."]
    assert axes[-1].get_xscale() == "log" and axes[-1].get_xlabel() == "band centre frequency (Hz)"


def test_spectrum_figure_draws_measured_and_reconstructions(basis, spectra):
    fig = plots.spectrum_figure(spectra, basis, variants=True)
    assert len(fig.axes) == len(spectra)
    for ax, (label, band_db) in zip(fig.axes, spectra):
        scores = basis.scores(band_db)
        assert ax.get_title() == label
        assert texts(ax.get_legend()) == ["measured", f"S1 (t1 = {scores[0]:+.1f})", "S1:8", "S2:8", "M"]
        measured, s1, s18, s28, mean = (line.get_ydata() for line in ax.get_lines())
        np.testing.assert_allclose(measured, normalise_db(band_db))
        np.testing.assert_allclose(s1, basis.reconstruct(scores, components=slice(0, 1)))
        np.testing.assert_allclose(s18, basis.reconstruct(scores, components=slice(0, None)))
        np.testing.assert_allclose(s28, basis.reconstruct(scores, components=slice(1, None)))
        np.testing.assert_array_equal(mean, basis.mean_db)
    # about M, the S1 lines of a dark (t1 < 0) and a bright recording tilt opposite ways
    tilts = [
        np.polyfit(np.log(basis.centres_hz), ax.get_lines()[1].get_ydata() - basis.mean_db, 1)[0] for ax in fig.axes
    ]
    assert tilts[0] < 0 < tilts[1]
    plain = plots.spectrum_figure(spectra[:1], basis)
    assert texts(plain.axes[0].get_legend())[2:] == ["S1:8"]  # no variants unless asked


def test_presets_figure_places_presets_by_balance_and_intensity(basis):
    fig = plots.presets_figure(PRESETS, basis)
    ax, ax2 = fig.axes[:2]
    (dots,) = ax.collections
    by_balance = sorted(PRESETS, key=lambda p: p[1])
    np.testing.assert_allclose(dots.get_offsets(), [[b, y] for y, (_, b, _) in enumerate(by_balance)])
    np.testing.assert_allclose(dots.get_sizes(), [30 + 170 * i for _, _, i in by_balance])
    assert [t.get_text() for t in ax.texts] == [name for name, _, _ in by_balance]
    assert texts(ax2.get_legend()) == ["balance -1", "balance +0", "balance +1"]
    for line, b in zip(ax2.get_lines(), (-1.0, 0.0, 1.0)):
        np.testing.assert_allclose(line.get_ydata(), basis.spectrum_for_balance(b))
    with pytest.raises(Exception, match="no presets"):
        plots.presets_figure([], basis)


def test_mds_figure_draws_rated_and_model_positions(mds):
    fig = plots.mds_figure(mds)
    (ax,) = fig.axes
    rated, model = ax.collections
    np.testing.assert_allclose(rated.get_offsets(), mds.rated)
    np.testing.assert_allclose(model.get_offsets(), mds.predicted)
    assert texts(ax.get_legend()) == ["rated (MDS of mean ratings)", "model (MDS of D, Procrustes)"]
    errors = [line for line in ax.get_lines() if len(line.get_xdata()) == 2]
    assert len(errors) == len(mds.names)
    for line, a, b in zip(errors, mds.rated, mds.predicted):
        np.testing.assert_allclose(np.column_stack([line.get_xdata(), line.get_ydata()]), [a, b])
    labels = [t.get_text() for t in ax.texts]
    assert labels[: len(mds.names)] == list(mds.names)
    r = mds.component_r[0]
    assert labels[-1] == f"  V1 (r = {r[0]:+.2f}, {r[1]:+.2f})"
    assert ax.get_title() == f"Perceptual space (Procrustes RMS error {mds.procrustes_rms:.3f})"
    assert plots.mds_figure(mds, title="mine").axes[0].get_title() == "mine"


# ---------------------------------------------------------------------- the PNG files
def test_basis_png_shows_the_components(basis, tmp_path):
    img = read_png(plots.plot_basis(basis, tmp_path / "b.png"))
    assert share_of(img, BLUE) > 1e-3 and share_of(img, ORANGE) > 3e-3  # V1 in blue, V2..V8 in orange


def test_spectrum_png_shows_the_s1_line(basis, spectra, tmp_path):
    img = read_png(plots.plot_spectrum(spectra, basis, tmp_path / "s.png", variants=True))
    assert share_of(img, RED) > 1e-3 and share_of(img, BLUE) > 1e-3


def test_presets_png(basis, tmp_path):
    img = read_png(plots.plot_presets(PRESETS, basis, tmp_path / "p.png"))
    assert share_of(img, RED) > 1e-3 and share_of(img, BLUE) > 1e-3  # balance +1 and -1 spectra


def test_mds_png_shows_both_point_sets(mds, tmp_path):
    img = read_png(plots.plot_mds(mds, tmp_path / "m.png"))
    assert share_of(img, BLUE) > 1e-3 and share_of(img, RED) > 5e-4


def test_cli_plot_basis_and_presets(tmp_path, capsys):
    from vibsynth.cli import main

    assert main(["plot", "basis", "-o", str(tmp_path / "b.png")]) == 0
    read_png(tmp_path / "b.png")
    code = main(["plot", "presets", "-o", str(tmp_path / "p.png")])
    if code == 0:
        read_png(tmp_path / "p.png")
    else:  # no presets installed: a clear one-line message
        assert "preset" in capsys.readouterr().err


# ---------------------------------------------------------------------- global state
def test_plots_leave_matplotlib_global_state_alone(basis, spectra, mds, tmp_path):
    import sys

    def snapshot():
        return dict(matplotlib.rcParams.copy())  # copy(): reading "backend" would resolve it

    # a user style that differs from the plots' own in every key they set
    user = {key: (not value if isinstance(value, bool) else value / 2) for key, value in plots._RC.items()}
    with matplotlib.rc_context(user):
        before = snapshot()
        pyplot_loaded = "matplotlib.pyplot" in sys.modules
        calls = [
            lambda: plots.plot_basis(basis, tmp_path / "b.png"),
            lambda: plots.plot_spectrum(spectra, basis, tmp_path / "s.png", variants=True),
            lambda: plots.plot_presets(PRESETS, basis, tmp_path / "p.png"),
            lambda: plots.plot_mds(mds, tmp_path / "m.png"),
            lambda: plots.basis_figure(basis),
        ]
        for call in calls:
            call()
            assert snapshot() == before
        assert ("matplotlib.pyplot" in sys.modules) == pyplot_loaded  # no pyplot, so no figure registry
        # the plots' own style was in force while drawing
        fig = plots.basis_figure(basis)
        assert fig.axes[0].yaxis.label.get_fontsize() == plots._RC["axes.labelsize"]
        assert fig.axes[0].xaxis.get_gridlines()[0].get_visible()


def test_missing_matplotlib_message(basis, tmp_path, monkeypatch):
    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ImportError("No module named 'matplotlib'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(MissingDependencyError, match=r"needs matplotlib: pip install 'vibsynth\[research\]'"):
        plots.plot_basis(basis, tmp_path / "b.png")
    assert not (tmp_path / "b.png").exists()
