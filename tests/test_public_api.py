"""The public API in ``vibsynth/__init__.py``: lazy names, one version, ``render`` and ``analyze``."""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vibsynth
from vibsynth.errors import InputError, ParameterError

ROOT = Path(__file__).resolve().parents[1]
PUBLIC = [
    "Engine",
    "Basis",
    "analyze",
    "synthesize",
    "render",
    "follow",
    "load_config",
    "Preset",
    "Client",
    "VibsynthError",
]


def _python(code: str) -> str:
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    return run.stdout.strip()


def test_import_vibsynth_is_light():
    code = (
        "import sys, vibsynth\n"
        "light = not any(m in sys.modules for m in ('numpy', 'scipy', 'pythonosc'))\n"
        "vibsynth.__version__, vibsynth.VibsynthError\n"
        "print(light, 'numpy' in sys.modules)\n"
    )
    assert _python(code) == "True False"
    # the client needs no numpy either
    assert _python("import sys, vibsynth; vibsynth.Client; print('numpy' in sys.modules)") == "False"


def test_public_names_resolve_lazily():
    assert sorted(vibsynth.__all__) == sorted([*PUBLIC, "__version__"])
    for name in vibsynth.__all__:
        assert getattr(vibsynth, name) is not None
        assert name in dir(vibsynth)
    from vibsynth.app.client import Client
    from vibsynth.dsp.basis import Basis
    from vibsynth.dsp.synthesis import synthesize
    from vibsynth.engine.engine import Engine
    from vibsynth.errors import VibsynthError
    from vibsynth.settings.config import load_config
    from vibsynth.settings.presets import Preset

    assert vibsynth.Client is Client and vibsynth.Engine is Engine and vibsynth.Basis is Basis
    assert vibsynth.synthesize is synthesize and vibsynth.load_config is load_config
    assert vibsynth.Preset is Preset and vibsynth.VibsynthError is VibsynthError
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        vibsynth.nope  # noqa: B018
    with pytest.raises(ImportError):
        exec("from vibsynth import nope", {})


def test_version_is_written_once_in_its_module():
    version_file = ROOT / "vibsynth" / "_version.py"
    written = re.search(r'(?m)^__version__ = "([^"]+)"$', version_file.read_text()).group(1)
    assert vibsynth.__version__ == importlib.metadata.version("vibsynth") == written
    from vibsynth import __version__
    from vibsynth._version import __version__ as below

    assert __version__ == below == written
    pyproject = (ROOT / "pyproject.toml").read_text()
    project = pyproject.split("\n[project]\n", 1)[1].split("\n[", 1)[0]
    assert 'dynamic = ["version"]' in project and not re.search(r"(?m)^version\s*=", project)
    assert 'version = { attr = "vibsynth._version.__version__" }' in pyproject  # read from the module
    out = subprocess.run(
        [sys.executable, "-m", "vibsynth", "--version"], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert out.stdout.strip() == f"vibsynth {written}"
    # no other version string in the package
    for path in (ROOT / "vibsynth").rglob("*.py"):
        if path == version_file:
            continue
        text = path.read_text(encoding="utf-8")
        assert not re.search(r"__version__\s*=", text), path
        assert f'"{written}"' not in text, path


def test_render_through_the_engine():
    x = vibsynth.render(0.8, 0.5, 1.0, fs=24000.0, seed=3)
    assert x.shape == (24000,) and x.dtype == np.float32
    assert np.array_equal(x, vibsynth.render(0.8, 0.5, 1.0, fs=24000.0, seed=3))
    assert not np.array_equal(x, vibsynth.render(0.8, 0.5, 1.0, fs=24000.0, seed=4))
    assert 0.0 < np.abs(x).max() < 0.891  # the engine's limiter ceiling
    a = vibsynth.analyze(x, fs=24000.0)
    assert a.intensity_knob == pytest.approx(0.8, abs=0.03)
    assert a.balance == pytest.approx(0.5, abs=0.1)
    louder = vibsynth.render(1.0, 0.5, 1.0, fs=24000.0, seed=3)
    assert vibsynth.analyze(louder, fs=24000.0).level_db == pytest.approx(a.level_db + 8.0, abs=0.3)  # 0.2 x 40 dB
    assert not np.any(vibsynth.render(0.0, 0.0, 0.1, seed=1))
    for bad in (
        dict(intensity=1.5, balance=0.0, seconds=1.0),
        dict(intensity=0.5, balance=float("nan"), seconds=1.0),
        dict(intensity=0.5, balance=0.0, seconds=0.0),
        dict(intensity=0.5, balance=0.0, seconds=1.0, fs=1000.0),
        dict(intensity=0.5, balance=0.0, seconds=1.0, seed=-1),
    ):
        with pytest.raises(ParameterError):
            vibsynth.render(**bad)


def test_analyze_takes_samples_or_a_file(tmp_path):
    from vibsynth.formats.recordings import write_wav

    x = vibsynth.render(0.6, -1.0, 1.0, seed=5)
    path = tmp_path / "texture.wav"
    write_wav(path, x, 48000.0)
    from_file = vibsynth.analyze(path)
    from_array = vibsynth.analyze(x, fs=48000)
    assert from_file.balance == pytest.approx(from_array.balance, abs=1e-6)
    assert from_file.balance == pytest.approx(-1.0, abs=0.1)
    with pytest.raises(ParameterError, match="fs"):
        vibsynth.analyze(x)
    with pytest.raises(InputError):
        vibsynth.analyze(tmp_path / "missing.wav")


def test_follow_uses_the_shipped_basis():
    fs = 8000.0
    x = np.random.default_rng(3).standard_normal(int(fs))
    result = vibsynth.follow(x, fs)
    assert result.mode == "vibration" and len(result) > 300
    assert np.all((result.intensity > 0) & (result.intensity <= 1))
    with pytest.raises(ParameterError, match="focus"):
        vibsynth.follow(x, fs, mode="audio", focus="voices")
