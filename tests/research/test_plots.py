"""Each plot renders a non-trivial PNG (size, non-uniform pixels)."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

pytest.importorskip("matplotlib", reason="plots need matplotlib (vibsynth[research])")

from vibsynth.research import plots  # noqa: E402
from vibsynth.research.dissim import MissingDependencyError, mds_map, read_ratings  # noqa: E402


def check_png(path, min_side=300):
    import matplotlib.image as mpimg

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    img = mpimg.imread(path)
    assert min(img.shape[:2]) >= min_side
    grey = img[..., :3].mean(axis=-1)
    assert grey.std() > 0.05  # not a blank canvas
    assert (grey < 0.5).mean() > 0.005  # some dark ink (lines, text)


def test_basis_plot(basis, tmp_path):
    check_png(plots.plot_basis(basis, tmp_path / "b.png"))


def test_spectrum_plot(basis, tmp_path, rng):
    spectra = [(f"s{i}", basis.mean_db + t * basis.v1 + rng.normal(0, 1, 30) - 40) for i, t in enumerate([-20, 25])]
    check_png(plots.plot_spectrum(spectra, basis, tmp_path / "s.png", variants=True))


def test_presets_plot(basis, tmp_path):
    items = [("rough", -0.8, 0.7), ("mid", 0.0, 0.5), ("bright", 1.1, 0.9)]
    check_png(plots.plot_presets(items, basis, tmp_path / "p.png"))


def test_mds_plot(tmp_path, rng):
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
    check_png(plots.plot_mds(mds_map(table, scores[order]), tmp_path / "m.png"))


def test_cli_plot_basis_and_presets(tmp_path, capsys):
    from vibsynth.cli import main

    assert main(["plot", "basis", "-o", str(tmp_path / "b.png")]) == 0
    check_png(tmp_path / "b.png")
    code = main(["plot", "presets", "-o", str(tmp_path / "p.png")])
    if code == 0:
        check_png(tmp_path / "p.png")
    else:  # no presets installed: a clear one-line message
        assert "preset" in capsys.readouterr().err


def test_missing_matplotlib_message(basis, tmp_path, monkeypatch):
    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ImportError("No module named 'matplotlib'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(MissingDependencyError, match=r"needs matplotlib: pip install 'vibsynth\[research\]'"):
        plots.plot_basis(basis, tmp_path / "b.png")
