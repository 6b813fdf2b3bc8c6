"""The wheel installs anywhere with no compiler and no root, and runs from outside the source (issue 32, item 4).

Once per run (nothing is cached across runs), in a temporary folder:

1. the files git tracks are copied out of the working tree and a wheel is built from the copy,
   as a user or cibuildwheel would (``pip wheel``, build isolation: setuptools and wheel come
   from the package index as ``[build-system]`` asks);
2. a fresh venv (no system site packages, no pip of its own) gets the wheel and its
   dependencies with ``--only-binary=:all:`` and ``CC``/``CXX`` set to ``/bin/false``: nothing
   is compiled (pip fetches the dependencies' wheels from the package index);
3. the venv's ``vibsynth`` runs from a temporary folder with ``HOME`` and ``XDG_*`` inside it:
   ``--version``, ``render``, ``analyze``, ``preset list``, ``clip list``, ``serve --output null``
   answering ``/ping``, its studio page with every JS/CSS file, and its OSCQuery tree;
4. the bad input: PortAudio missing (``import sounddevice`` raising what it raises without
   ``libportaudio2``: OSError), the sounddevice package missing, libsndfile missing (soundfile
   raising OSError): ``serve`` falls back to the null output with one line saying what is
   missing, ``render`` works, a FLAC is refused in one line; never a traceback.

The C sources and headers (``*.c``, ``*.h``) stay out of the wheel: they are build inputs,
shipped in the sdist (MANIFEST.in); the wheel carries the compiled extensions and their
``.pyi`` stubs. Every subprocess has a timeout. The module runs in the unit phase (marker
``packaging``); most of its time is the C build and pip installing numpy, scipy and the other
wheels (seconds printed with ``-s``): about 7 minutes on a 2-core machine shared at a load of 15.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.request
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import tomllib

from tests.serveutil import stop_serve

ROOT = Path(__file__).resolve().parents[1]
EXTENSIONS = ("vibsynth/engine/_core", "vibsynth/engine/_input", "vibsynth/control/osc/_fast")
SOURCES_ONLY = (".c", ".h")  # in the sdist, not in the wheel
TOKEN = "packaging-test-token-0123456789"
pytestmark = pytest.mark.packaging  # runs in the unit phase; `-m "not packaging"` leaves it out while iterating

RENDER = ("render", "--balance", "0", "--intensity", "0.5", "--seconds", "1", "-q")

# Stands in for a machine without PortAudio / libsndfile / a package: ``import NAME`` raises
# what the real import raises there. Loaded by the venv's Python through PYTHONPATH.
SITECUSTOMIZE = """
import os
import sys


class _Missing:
    def find_spec(self, name, path=None, target=None):
        how = os.environ.get("PACKAGING_TEST_" + name.upper())
        if how == "oserror":
            library = {"sounddevice": "PortAudio", "soundfile": "sndfile"}[name]
            raise OSError(library + " library not found")
        if how == "missing":
            raise ModuleNotFoundError("No module named " + repr(name), name=name)
        return None


sys.meta_path.insert(0, _Missing())
"""


@dataclass
class Installed:
    """The built wheel and the venv it was installed into."""

    wheel: Path
    venv: Path
    work: Path  # the folder the commands run in (outside any source tree)
    env: dict[str, str]
    seconds: dict[str, float]

    @property
    def vibsynth(self) -> str:
        return str(self.venv / "bin" / "vibsynth")

    def run(self, *args: str, timeout: float = 60, extra_env: dict[str, str] | None = None, check: bool = True):
        done = subprocess.run(
            [self.vibsynth, *args],
            cwd=self.work,
            env={**self.env, **(extra_env or {})},
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        if check and done.returncode != 0:
            raise AssertionError(f"vibsynth {' '.join(args)} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
        assert "Traceback" not in done.stdout + done.stderr
        return done


def _tracked(under: str = "") -> list[str]:
    out = subprocess.run(
        ["git", "ls-files", "-z", *([under] if under else [])], cwd=ROOT, capture_output=True, check=True, timeout=60
    ).stdout.decode()
    return [name for name in out.split("\0") if name and (ROOT / name).is_file()]


def _clean_env(folder: Path) -> dict[str, str]:
    """No VIBSYNTH_* of the caller, HOME and XDG folders inside ``folder``, no compiler.

    The PIP_* variables stay: they are how this machine reaches the package index.
    """
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIBSYNTH_", "PYTHON", "VIRTUAL_ENV"))}
    for key in ("HOME", "XDG_CONFIG_HOME", "XDG_DATA_HOME", "XDG_CACHE_HOME", "XDG_STATE_HOME"):
        env[key] = str(folder / key.lower())
    env.update(CC="/bin/false", CXX="/bin/false", PIP_DISABLE_PIP_VERSION_CHECK="1")
    return env


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    base = tmp_path_factory.mktemp("packaging")
    seconds: dict[str, float] = {}
    # 1. the tracked files only: what a clone has (no build/, no egg-info, no compiled module)
    source = base / "src"
    for name in _tracked():
        target = source / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, target)
    env = _clean_env(base)
    venv = base / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    pip = [sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "-q", "--no-cache-dir"]
    pip += ["--no-compile", "--only-binary=:all:"]  # (no .pyc of scipy's thousands of files: time)
    # 2a. the dependencies, while the wheel builds (two cores: the build compiles, pip mostly waits)
    with open(ROOT / "pyproject.toml", "rb") as f:
        dependencies = tomllib.load(f)["project"]["dependencies"]
    started = time.monotonic()
    log = base / "pip-dependencies.log"
    with open(log, "w") as out:
        deps = subprocess.Popen([*pip, *dependencies], env=env, stdout=out, stderr=subprocess.STDOUT)
    try:
        built = subprocess.run(
            [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(base / "dist"), str(source)],
            env={**env, "CC": os.environ.get("CC", "cc"), "CXX": os.environ.get("CXX", "c++")},  # this step compiles
            capture_output=True,
            text=True,
            timeout=240,
        )
        assert built.returncode == 0, f"pip wheel failed:\n{built.stdout}\n{built.stderr}"
        seconds["build"] = time.monotonic() - started
        deps.wait(timeout=300)
    finally:
        if deps.poll() is None:
            deps.kill()
            deps.wait()
    assert deps.returncode == 0, f"pip install of the dependencies failed:\n{log.read_text()}"
    (wheel,) = (base / "dist").glob("vibsynth-*.whl")
    # 2b. the wheel, checked against its own requirements (all there: pip compiles and fetches nothing)
    done = subprocess.run([*pip, str(wheel)], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"pip install failed:\n{done.stdout}\n{done.stderr}"
    seconds["install"] = time.monotonic() - started
    work = base / "work"
    work.mkdir()
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}/usr/bin{os.pathsep}/bin"
    (base / "hide").mkdir()
    (base / "hide" / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env["PACKAGING_TEST_SITE"] = str(base / "hide")
    print(
        f"\nwheel {wheel.name} {wheel.stat().st_size / 1e6:.2f} MB; "
        + ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items())
    )
    return Installed(wheel, venv, work, env, seconds)


def test_the_wheel_holds_every_package_file_and_the_three_extensions(installed):
    names = set(zipfile.ZipFile(installed.wheel).namelist())
    tracked = _tracked("vibsynth")
    wanted = [name for name in tracked if not name.endswith(SOURCES_ONLY)]
    assert len(wanted) > 150 and any(name.endswith(".yaml") for name in wanted)
    missing = sorted(set(wanted) - names)
    assert not missing, f"tracked package files missing from the wheel (pyproject.toml package-data): {missing}"
    # the kinds the issue names, each present
    for pattern in (
        r"vibsynth/data/presets/wood\.yaml",
        r"vibsynth/data/clips/impact\.yaml",
        r"vibsynth/data/layouts/vest16\.yaml",
        r"vibsynth/data/config/actuators/flat\.yaml",
        r"vibsynth/data/schema/config\.schema\.json",
        r"vibsynth/data/default_basis\.yaml",
        r"vibsynth/control/studio/static/index\.html",
        r"vibsynth/control/studio/static/studio\.css",
        r"vibsynth/control/studio/static/js/main\.js",
        r"vibsynth/app/lab/static/lab\.css",
        r"vibsynth/app/clips/clip_tab\.js",
        r"vibsynth/engine/_core\.pyi",
        r"vibsynth/py\.typed",
    ):
        assert any(re.fullmatch(pattern, name) for name in names), pattern
    for ext in EXTENSIONS:
        built = [n for n in names if n.startswith(ext + ".") and n.endswith((".so", ".pyd"))]
        assert len(built) == 1, (ext, built)
    assert not [n for n in names if n.endswith(SOURCES_ONLY)], "C sources belong in the sdist"
    # nothing but the package and its metadata
    assert {n.split("/")[0] for n in names} == {
        "vibsynth",
        installed.wheel.name.split("-")[0] + "-" + installed.wheel.name.split("-")[1] + ".dist-info",
    }


def test_the_commands_run_from_a_folder_outside_the_source(installed):
    import soundfile

    from vibsynth._version import __version__

    assert installed.run("--version").stdout.strip() == f"vibsynth {__version__}"
    # it is the wheel's package that runs, not the source tree's
    where = subprocess.run(
        [str(installed.venv / "bin" / "python"), "-c", "import vibsynth; print(vibsynth.__file__)"],
        cwd=installed.work,
        env=installed.env,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    ).stdout.strip()
    assert Path(where).is_relative_to(installed.venv)

    args = ("render", "--balance", "0.5", "--intensity", "0.6", "--seconds", "2", "--seed", "7", "-q")
    installed.run(*args, "-o", "x.wav")
    x, fs = soundfile.read(installed.work / "x.wav", dtype="float64")
    assert fs == 48000 and x.shape == (96000,)
    rms_db = 20 * np.log10(np.sqrt(np.mean(x**2)))
    assert -80 < rms_db < -20
    # the same samples as the source tree renders
    subprocess.run(
        [str(Path(sys.executable).parent / "vibsynth"), *args, "-o", str(installed.work / "tree.wav")],
        check=True,
        capture_output=True,
        timeout=120,
        env={**installed.env, "PATH": os.environ["PATH"]},
    )
    tree, _ = soundfile.read(installed.work / "tree.wav", dtype="float64")
    np.testing.assert_array_equal(x, tree)

    analyzed = installed.run("analyze", "x.wav").stdout
    row = next(line.split() for line in analyzed.splitlines() if line.startswith("x.wav"))
    duration, rate, level, knob, balance = (float(v) for v in row[1:6])
    assert (duration, rate) == (2.0, 48000.0)
    assert knob == pytest.approx(0.6, abs=0.01) and balance == pytest.approx(0.5, abs=0.05)  # what was asked
    del level  # (the knob's level in the model's units: checked by tests/cli/; here the numbers of the tree's analyze)
    tree_row = (
        subprocess.run(
            [str(Path(sys.executable).parent / "vibsynth"), "analyze", str(installed.work / "x.wav")],
            check=True,
            capture_output=True,
            text=True,
            timeout=120,
            env={**installed.env, "PATH": os.environ["PATH"]},
        )
        .stdout.splitlines()[-1]
        .split()[1:]
    )
    assert row[1:] == tree_row

    for kind in ("preset", "clip"):  # every shipped one listed, from the wheel's data (the user folder is empty)
        listing = installed.run(kind, "list").stdout
        shipped = sorted(p.stem for p in (ROOT / "vibsynth" / "data" / f"{kind}s").glob("*.yaml"))
        listed = sorted(line.split()[0] for line in listing.splitlines() if "shipped" in line.split())
        assert len(shipped) >= 5 and listed == shipped
        assert re.search(
            rf"^{len(shipped)} {kind}s; user folder: {re.escape(installed.env['XDG_DATA_HOME'])}", listing, re.M
        )


def _serve(installed: Installed, *args: str, extra_env: dict[str, str] | None = None) -> tuple[subprocess.Popen, Path]:
    log = installed.work / f"serve-{time.monotonic_ns()}.log"
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [installed.vibsynth, "serve", "--osc-port", "0", "--oscquery-port", "0", *args],
            cwd=installed.work,
            env={**installed.env, **(extra_env or {})},
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    return proc, log


def _wait_for_lines(proc: subprocess.Popen, log: Path, *patterns: str, timeout: float = 60) -> str:
    deadline = time.monotonic() + timeout
    while True:
        text = log.read_text()
        if all(re.search(p, text, re.M) for p in patterns):
            return text
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"serve did not print {patterns} (exit {proc.poll()}):\n{text}")
        time.sleep(0.05)


def _get(url: str, token: str | None = None) -> bytes:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    with urllib.request.urlopen(urllib.request.Request(url, headers=headers), timeout=10) as response:
        assert response.status == 200
        return response.read()


def test_serve_answers_osc_serves_the_studio_and_the_oscquery_tree(installed):
    proc, log = _serve(installed, "--output", "null", "--studio-port", "0", "--studio-token", TOKEN)
    try:
        text = _wait_for_lines(proc, log, r"^studio: http://\S+$", r"^oscquery: http://\S+$", r"OSC on udp://")
        osc_port = re.search(r"OSC on udp://127\.0\.0\.1:(\d+)/", text).group(1)
        ping = installed.run("send", "--port", osc_port, "--wait-reply", "5", "/vibsynth/ping", "42")
        assert re.search(r"^/vibsynth/pong i 42$", ping.stdout, re.M), ping.stdout

        studio = re.search(r"^studio: (http://[^/]+)/\?token=(\S+)$", text, re.M)
        assert studio.group(2) == TOKEN
        page = _get(studio.group(1) + "/", TOKEN).decode()
        linked = re.findall(r'(?:href|src)="(/static/[^"]+)"', page)
        assert "/static/studio.css" in linked and "/static/js/main.js" in linked
        static = ROOT / "vibsynth" / "control" / "studio" / "static"
        files = sorted(p for p in static.rglob("*") if p.suffix in (".js", ".css"))
        assert len(files) >= 5
        for path in files:  # every script the page's modules import, and the style sheet
            served = _get(f"{studio.group(1)}/static/{path.relative_to(static).as_posix()}", TOKEN)
            assert served == path.read_bytes(), path
        # the tabs other parts add (clips, lab, calibrate): their scripts and the lab's styles
        state = json.loads(_get(studio.group(1) + "/api/state", TOKEN))
        app = ROOT / "vibsynth" / "app"
        shipped = {
            "/ext/clips/tab.js": app / "clips" / "clip_tab.js",
            "/ext/lab/tab.js": app / "lab" / "static" / "lab_tab.js",
            "/ext/calibrate/tab.js": app / "lab" / "static" / "calibrate_tab.js",
            "/ext/lab/lab.css": app / "lab" / "static" / "lab.css",
        }
        assert sorted(e["script"] for e in state["extensions"]) == sorted(u for u in shipped if u.endswith(".js"))
        for url, path in shipped.items():
            assert _get(studio.group(1) + url, TOKEN) == path.read_bytes(), url
        with pytest.raises(urllib.error.HTTPError):  # the token is still required
            _get(studio.group(1) + "/static/studio.css")

        oscquery = re.search(r"^oscquery: (http://\S+)$", text, re.M).group(1)
        tree = json.loads(_get(oscquery))
        assert tree["FULL_PATH"] == "/" and "vibsynth" in tree["CONTENTS"]
        intensity = tree["CONTENTS"]["vibsynth"]["CONTENTS"]["intensity"]
        assert intensity["TYPE"] == "f"
        host_info = json.loads(_get(oscquery.rstrip("/") + "/?HOST_INFO"))
        assert host_info["OSC_PORT"] == int(osc_port)
    finally:
        stop_serve(proc)
    assert proc.returncode == 0 and "Traceback" not in log.read_text()


def _hidden(installed: Installed, **modules: str) -> dict[str, str]:
    extra = {"PYTHONPATH": installed.env["PACKAGING_TEST_SITE"]}
    extra.update({f"PACKAGING_TEST_{name.upper()}": how for name, how in modules.items()})
    return extra


def _serve_briefly(installed: Installed, *args: str, extra_env: dict[str, str]) -> str:
    proc, log = _serve(installed, "--no-studio", "--seconds", "1", *args, extra_env=extra_env)
    try:
        proc.wait(timeout=90)
    finally:
        if proc.poll() is None:
            stop_serve(proc)
    text = log.read_text()
    assert proc.returncode == 0, text
    assert "Traceback" not in text
    return text


def _one_line(text: str, says: str) -> str:
    lines = [line for line in text.splitlines() if says in line]
    assert len(lines) == 1, text
    return lines[0]


def test_without_portaudio_and_libsndfile_serve_falls_back_in_one_line_and_render_works(installed):
    """What sounddevice raises without libportaudio2 and soundfile without libsndfile: OSError at import."""
    import soundfile

    hidden = _hidden(installed, sounddevice="oserror", soundfile="oserror")
    text = _serve_briefly(installed, extra_env=hidden)  # the default output: auto
    line = _one_line(text, "PortAudio is not available (PortAudio library not found); install libportaudio2")
    assert line.startswith("vibsynth: warning: ") and "falling back to the null output" in line
    assert re.search(r"^vibsynth: serving 1 channel\(s\) on null output", text, re.M)

    installed.run(*RENDER, "-o", "n.wav", extra_env=hidden)
    n, fs = soundfile.read(installed.work / "n.wav")
    assert fs == 48000 and n.shape == (48000,) and np.sqrt(np.mean(n**2)) > 1e-4
    # Follow reads WAV without libsndfile; another format is one line naming what is missing
    rng = np.random.default_rng(3)
    sound = 0.2 * rng.standard_normal(48000)
    soundfile.write(installed.work / "sound.wav", sound, 48000, subtype="PCM_16")
    soundfile.write(installed.work / "sound.flac", sound, 48000)
    installed.run("render", "--follow", "sound.wav", "-q", "-o", "f.wav", extra_env=hidden)
    follow, fs = soundfile.read(installed.work / "f.wav")
    assert fs == 48000 and len(follow) > 0 and np.any(follow != 0)
    refused = installed.run("render", "--follow", "sound.flac", "-q", "-o", "g.wav", extra_env=hidden, check=False)
    assert refused.returncode == 1
    (line,) = refused.stderr.strip().splitlines()
    assert line.startswith("vibsynth: error: ") and "soundfile package is unusable (sndfile library not found)" in line


def test_without_the_sounddevice_package_serve_falls_back_in_one_line(installed):
    """An install without its dependencies (pip --no-deps): auto falls back, a named sound card is one error."""
    hidden = _hidden(installed, sounddevice="missing")
    says = "the sounddevice package is not installed"
    line = _one_line(_serve_briefly(installed, extra_env=hidden), says)
    assert line.startswith("vibsynth: warning: ") and "falling back to the null output" in line
    args = ("serve", "--output", "sounddevice", "--seconds", "1", "--no-studio", "--osc-port", "0")
    refused = installed.run(*args, "--oscquery-port", "0", extra_env=hidden, check=False)
    assert refused.returncode != 0
    last = refused.stderr.strip().splitlines()[-1]
    assert last.startswith("vibsynth: error: ") and says in last


def _second_python() -> str | None:
    """A CPython other than the one running the tests (3.12 beside 3.11, or 3.11 beside 3.12)."""
    version = "3.12" if sys.version_info[:2] != (3, 12) else "3.11"
    candidates = [
        str(p) for p in sorted((Path.home() / ".pyenv" / "versions").glob(f"{version}.*/bin/python{version}"))
    ]
    candidates.append(shutil.which(f"python{version}") or "")
    for candidate in candidates:
        works = candidate and subprocess.run([candidate, "-c", ""], capture_output=True, timeout=60).returncode == 0
        if works:
            return candidate
    return None


def test_the_same_wheel_runs_on_a_second_python(installed):
    """One wheel for every supported Python needs the stable ABI (issue 32 item 1): until the
    extensions build with Py_LIMITED_API the wheel is tagged for one Python and this skips."""
    tag = installed.wheel.name.removesuffix(".whl").split("-")[-2]
    if tag != "abi3":
        pytest.skip(f"the wheel is {tag}, not abi3: one Python only until the limited-API build (issue 32 item 1)")
    python = _second_python()
    assert python, "no second CPython (python3.12) to install the abi3 wheel into"
    venv = installed.work.parent / "venv2"
    subprocess.run([python, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    pip = [sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "-q", "--no-cache-dir"]
    done = subprocess.run(
        [*pip, "--no-compile", "--only-binary=:all:", str(installed.wheel)],
        env=installed.env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, f"pip install failed:\n{done.stdout}\n{done.stderr}"
    second = Installed(installed.wheel, venv, installed.work, installed.env, {})
    from vibsynth._version import __version__

    assert second.run("--version").stdout.strip() == f"vibsynth {__version__}"
    second.run(*RENDER, "-o", "second.wav")
    assert second.run("analyze", "second.wav").stdout.count("second.wav") == 1
