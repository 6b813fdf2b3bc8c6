"""Stimulus sets: a folder of WAVs, shipped or user presets, or the engine's own renders.

Every stimulus has an id (shown to the experimenter and written in the CSV, never shown to a
participant), its samples at its own rate, and its parameters: where it came from and what
the paper's analysis measures of it (80-200 Hz band level, broadband level, t1..t8).

A set is prepared for a session in two steps (:func:`prepare`):

1. **normalisation** of each stimulus: ``"std"`` (equal standard deviation, the paper's
   preparation for experiment 1), ``"band"`` (equal 80-200 Hz band level: iso-intense by the
   paper's intensity model, for sets not equalised by participants), or ``"none"``;
2. **one gain for the whole set**, so that its median stimulus plays at the level of the
   intensity knob ``lab.level``: relative levels stay as step 1 left them, and whatever
   the files' scale (an accelerometer's m/s^2 or full-scale PCM), the actuator gets a level
   the engine's own textures use.

Stimuli are cut to the protocol's duration (the middle of a longer recording: the paper kept
"one second during which the scanning speed was roughly constant").
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from vibsynth.dsp.analysis import analyze, variant_spectra
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB, knob_to_level_db
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.files import size_limit_message
from vibsynth.formats.recordings import read_recording
from vibsynth.research.lab.protocol import VERSION_TAGS, VERSIONS

if TYPE_CHECKING:
    from vibsynth.dsp.basis import Basis
    from vibsynth.settings.presets import Preset

__all__ = [
    "MAX_STIMULI",
    "MAX_WAV_BYTES",
    "SET_MANIFEST",
    "RENDERS_DEFAULT_COUNT",
    "REFERENCE_RATE_HZ",
    "Normalise",
    "Stimulus",
    "StimulusSet",
    "SetSpec",
    "parse_set_spec",
    "SINE_MIN_HZ",
    "SINE_MAX_HZ",
    "SINE_COUNT",
    "SINE_REFERENCE_HZ",
    "DEFAULT_SINES_HZ",
    "parse_sines",
    "sine",
    "load_sines",
    "sine_id",
    "stimulus_id",
    "measure",
    "load_folder",
    "load_presets",
    "load_renders",
    "load_set",
    "prepare",
    "reference_noise",
    "resynthesis_versions",
    "resampled",
]

#: At most this many stimuli per set: 60 stimuli are 1,830 pairs (the paper used 18, 171 pairs).
MAX_STIMULI = 60
#: A WAV larger than this is refused before it is read (an hour of 48 kHz float32 stereo is 1.4 GB;
#: a stimulus is a second of it).
MAX_WAV_BYTES = 256 << 20
#: The file that marks a folder as a stimulus set written by the lab (an equalised set).
SET_MANIFEST = "set.json"
SET_FORMAT = "vibsynth-lab-set"
#: Stimuli of ``renders`` when no count is given: balances evenly spaced from -1 to +1 (the 2nd to
#: the 98th percentile of the basis' database).
RENDERS_DEFAULT_COUNT = 8
RENDERS_BALANCE_SPAN = (-1.0, 1.0)
#: The reference white noise is white up to half this rate, as the paper's (stimuli at 2800 Hz).
REFERENCE_RATE_HZ = 2800.0
#: Streams drawn from a session's seed besides its trial order (numpy SeedSequence entropy [seed, stream]).
PHASES_STREAM, REFERENCE_STREAM, VERSIONS_STREAM = 1, 2, 3
#: Stimulus ids: letters, digits and ``_ . + -``; the file stem of a WAV with anything else replaced.
ID_RULE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,79}")

Normalise = Literal["std", "band", "none"]
NORMALISE_MODES: tuple[Normalise, ...] = ("std", "band", "none")
SetKind = Literal["folder", "presets", "renders", "sines"]

#: Iso-intensity sines (the paper's Fig. 1b, direct intensity matching with sines): 8-12
#: frequencies in 10-1000 Hz, matched to a reference sine (default 250 Hz, Verrillo's most
#: sensitive frequency); the default set is 10 frequencies log-spaced over the whole range.
SINE_MIN_HZ, SINE_MAX_HZ = 10.0, 1000.0
SINE_COUNT = (8, 12)
SINE_REFERENCE_HZ = 250.0
DEFAULT_SINES_HZ: tuple[float, ...] = tuple(float(f"{f:.3g}") for f in np.geomspace(SINE_MIN_HZ, SINE_MAX_HZ, 10))
#: Raised-cosine onset and offset of each sine (no click: its spectrum stays one line).
SINE_RAMP_S = 0.02


@dataclass(frozen=True)
class Stimulus:
    """One stimulus.

    Attributes
    ----------
    id : str
        Unique in its set; names its WAV in a session folder.
    samples : ndarray, shape (n_samples,)
        float64, mono.
    fs : float
        Sample rate in Hz.
    params : dict
        Where it came from (``source``, ``file``, ``preset``, ``balance``, ``version``...) and,
        after :func:`prepare`, what it measures (:func:`measure`) and the gain applied.
    """

    id: str
    samples: NDArray[np.float64]
    fs: float
    params: Mapping[str, Any] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        """Length in seconds."""
        return self.samples.size / self.fs


@dataclass(frozen=True)
class StimulusSet:
    """Stimuli of one experiment.

    Attributes
    ----------
    name : str
        What the experimenter picked (``presets``, ``renders:6``, a folder's path).
    kind : {"folder", "presets", "renders"}
    stimuli : tuple of Stimulus
    equalised : bool
        The set was equalised in intensity by participants (a set written by the lab from
        intensity sessions): it is played as it is.
    """

    name: str
    kind: SetKind
    stimuli: tuple[Stimulus, ...]
    equalised: bool = False

    @property
    def ids(self) -> list[str]:
        """The stimuli's ids, in set order."""
        return [s.id for s in self.stimuli]

    def by_id(self) -> dict[str, Stimulus]:
        """Stimuli by id."""
        return {s.id: s for s in self.stimuli}


# --------------------------------------------------------------------------- naming and specs
def stimulus_id(text: str) -> str:
    """A stimulus id made from a file stem or a preset name (other characters become ``_``)."""
    cleaned = re.sub(r"[^A-Za-z0-9_.+-]", "_", text)[:80].lstrip("_.+-")
    return cleaned or "stimulus"


@dataclass(frozen=True)
class SetSpec:
    """A parsed stimulus-set name: ``presets``, ``presets:a,b,c``, ``renders``, ``renders:N``, or a folder.

    Attributes
    ----------
    kind : {"folder", "presets", "renders"}
    names : tuple of str
        Presets named (empty: every preset).
    count : int
        Stimuli of ``renders``.
    folder : pathlib.Path or None
    """

    kind: SetKind
    names: tuple[str, ...] = ()
    count: int = RENDERS_DEFAULT_COUNT
    folder: Path | None = None
    freqs: tuple[float, ...] = ()

    @property
    def text(self) -> str:
        """The spec as typed (canonical)."""
        if self.kind == "sines":
            return "sines" if self.freqs == DEFAULT_SINES_HZ else "sines:" + ",".join(f"{f:g}" for f in self.freqs)
        if self.kind == "folder":
            return str(self.folder)
        if self.kind == "renders":
            return f"renders:{self.count}"
        return "presets" + (":" + ",".join(self.names) if self.names else "")


def parse_set_spec(text: str) -> SetSpec:
    """Parse what the experimenter typed or picked as a stimulus set.

    Parameters
    ----------
    text : str
        ``presets`` (every preset of the library), ``presets:cork,wood`` (those), ``renders``
        (:data:`RENDERS_DEFAULT_COUNT` textures of the engine on a balance grid), ``renders:N``,
        ``sines`` (iso-intensity sines at :data:`DEFAULT_SINES_HZ`), ``sines:F1,F2,...``
        (:func:`parse_sines`), or a folder of WAV files.

    Raises
    ------
    ParameterError
        Empty, a ``renders`` count outside 2..:data:`MAX_STIMULI`, an empty preset list, bad sines.
    """
    spec = text.strip() if isinstance(text, str) else ""
    if not spec or len(spec) > 4096 or "\x00" in spec:
        raise ParameterError(
            "stimulus set: give 'presets', 'presets:NAME,NAME,...', 'renders', 'renders:N', 'sines', "
            "'sines:F1,F2,...' or a folder"
        )
    head, _, tail = spec.partition(":")
    if head == "sines":
        return SetSpec("sines", freqs=parse_sines(tail) if tail else DEFAULT_SINES_HZ)
    if head == "presets":
        names = tuple(n.strip() for n in tail.split(",") if n.strip()) if tail else ()
        if tail and not names:
            raise ParameterError("stimulus set 'presets:': name at least one preset, e.g. presets:cork,wood")
        return SetSpec("presets", names=names)
    if head == "renders":
        count = RENDERS_DEFAULT_COUNT
        if tail:
            if not tail.strip().isdecimal() or not 2 <= int(tail) <= MAX_STIMULI:
                raise ParameterError(f"stimulus set 'renders:{tail[:20]}': the count must be 2..{MAX_STIMULI}")
            count = int(tail)
        return SetSpec("renders", count=count)
    return SetSpec("folder", folder=Path(spec).expanduser())


def parse_sines(text: str) -> tuple[float, ...]:
    """The frequencies of ``sines:F1,F2,...``: :data:`SINE_COUNT` distinct numbers in 10-1000 Hz, sorted.

    Raises
    ------
    ParameterError
        One message saying what is allowed, whatever is wrong (not numbers, too few or too many,
        outside the range, the same frequency twice).
    """
    rule = (
        f"sines:F1,F2,...: give {SINE_COUNT[0]}-{SINE_COUNT[1]} different frequencies in "
        f"{SINE_MIN_HZ:g}-{SINE_MAX_HZ:g} Hz, e.g. sines:10,20,40,80,160,250,400,1000"
    )
    parts = [p.strip().removesuffix("Hz").removesuffix("hz").strip() for p in text.split(",")]
    try:
        freqs = [float(p) for p in parts if len(p) <= 20]
    except ValueError:
        raise ParameterError(f"{rule} (got {text[:60]!r})") from None
    if (
        len(freqs) != len(parts)
        or not SINE_COUNT[0] <= len(freqs) <= SINE_COUNT[1]
        or not all(math.isfinite(f) and SINE_MIN_HZ <= f <= SINE_MAX_HZ for f in freqs)
        or len({round(f, 3) for f in freqs}) != len(freqs)
    ):
        raise ParameterError(f"{rule} (got {text[:60]!r})")
    return tuple(sorted(round(f, 3) for f in freqs))


def sine(freq_hz: float, *, fs: float, seconds: float, amplitude: float = 1.0) -> NDArray[np.float64]:
    """A sine of peak ``amplitude`` with :data:`SINE_RAMP_S` raised-cosine ramps at both ends.

    Returns
    -------
    samples : ndarray, shape (round(seconds * fs),)
    """
    if not 0 < freq_hz < fs / 2:
        raise ParameterError(f"a {freq_hz:g} Hz sine needs a sample rate above {2 * freq_hz:g} Hz, got {fs:g}")
    n = int(round(seconds * fs))
    x = amplitude * np.sin(2.0 * np.pi * freq_hz * np.arange(n) / fs)
    ramp = min(int(round(SINE_RAMP_S * fs)), n // 2)
    if ramp:
        window = 0.5 - 0.5 * np.cos(np.pi * np.arange(ramp) / ramp)
        x[:ramp] *= window
        x[n - ramp :] *= window[::-1]
    return np.asarray(x, dtype=np.float64)


def sine_id(freq_hz: float) -> str:
    """A sine's stimulus id: ``sine-250Hz``, ``sine-16.7Hz``."""
    return f"sine-{freq_hz:g}Hz"


def load_sines(
    freqs: Sequence[float], *, fs: float, seconds: float, amplitude: float = 1.0, basis: Basis | None = None
) -> StimulusSet:
    """Iso-intensity sines, all of one peak ``amplitude`` (one drive voltage), in frequency order.

    Parameters
    ----------
    freqs : sequence of float
        Hz (:func:`parse_sines` checks a typed list).
    fs, seconds : float
    amplitude : float
        Peak of every sine (``build`` levels it below the limiter for every allowed gain).
    basis : Basis, optional
        When given, each stimulus' params hold what :func:`measure` gives.

    Returns
    -------
    set : StimulusSet
        Kind ``sines``; params ``source`` (``sine``), ``frequency_hz``, ``amplitude``.
    """
    stimuli = []
    for f in freqs:
        samples = sine(f, fs=fs, seconds=seconds, amplitude=amplitude)
        params: dict[str, Any] = {"source": "sine", "frequency_hz": float(f), "amplitude": float(amplitude)}
        if basis is not None:
            params.update(measure(samples, fs, basis))
        stimuli.append(Stimulus(sine_id(f), samples, float(fs), params))
    text = SetSpec("sines", freqs=tuple(float(f) for f in freqs)).text
    return StimulusSet(text, "sines", tuple(stimuli))


# --------------------------------------------------------------------------- measuring
def measure(samples: NDArray[np.float64], fs: float, basis: Basis) -> dict[str, Any]:
    """What the paper's analysis measures of a stimulus.

    Parameters
    ----------
    samples : ndarray, shape (n_samples,)
    fs : float
    basis : Basis

    Returns
    -------
    params : dict
        ``level_db`` (80-200 Hz Butterworth band level, dB re unit RMS: the intensity model),
        ``broadband_db`` (power in 10-1000 Hz, dB), ``t1`` and ``scores`` (T1..T8), ``rms``,
        ``peak``, ``duration_s``, ``fs``.

    Raises
    ------
    ParameterError
        Shorter than 0.5 s, silent, or not finite.
    """
    from vibsynth.dsp.filterbank import bin_powers

    analysis = analyze(samples, fs=fs, basis=basis)
    freqs, power = bin_powers(samples, fs=fs)
    inside = (freqs >= 10.0) & (freqs <= 1000.0)
    broadband = float(power[inside].sum())
    return {
        "level_db": round(float(analysis.level_db), 4),
        "broadband_db": round(10.0 * math.log10(broadband), 4) if broadband > 0 else -math.inf,
        "t1": round(float(analysis.t1), 4),
        "scores": [round(float(v), 4) for v in analysis.scores],
        "rms": float(np.sqrt(np.mean(samples**2))),
        "peak": float(np.max(np.abs(samples))),
        "duration_s": samples.size / fs,
        "fs": float(fs),
    }


def _middle(samples: NDArray[np.float64], fs: float, seconds: float, where: str) -> NDArray[np.float64]:
    n = int(round(seconds * fs))
    if samples.size < n:
        raise InputError(
            f"{where}: {samples.size / fs:.2f} s long; stimuli are {seconds:g} s (lab.stimulus_s): "
            "use longer recordings or a shorter stimulus duration"
        )
    start = (samples.size - n) // 2
    return np.ascontiguousarray(samples[start : start + n], dtype=np.float64)


# --------------------------------------------------------------------------- loaders
def _wav_files(folder: Path) -> list[Path]:
    if not folder.exists():
        raise InputError(f"{folder}: no such folder")
    if not folder.is_dir():
        raise InputError(f"{folder}: is not a folder (a stimulus set is a folder of WAV files)")
    found: list[Path] = []
    try:
        for i, entry in enumerate(os.scandir(folder)):
            if i >= 100_000:
                raise InputError(f"{folder}: over 100,000 entries; put the stimuli in a folder of their own")
            if entry.name.lower().endswith(".wav") and not entry.name.startswith(".") and entry.is_file():
                found.append(Path(entry.path))
    except OSError as exc:
        raise InputError(f"{folder}: cannot list ({exc.strerror or exc})") from None
    if not found:
        raise InputError(f"{folder}: no WAV files (a stimulus set is a folder of .wav files)")
    if len(found) > MAX_STIMULI:
        raise InputError(f"{folder}: {len(found)} WAV files; a set has at most {MAX_STIMULI} stimuli")
    return sorted(found)


def _read_manifest(folder: Path) -> dict[str, Any] | None:
    from vibsynth.formats.files import read_text

    path = folder / SET_MANIFEST
    if not path.is_file():
        return None
    try:
        data = json.loads(read_text(path, what="a stimulus-set manifest"))
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    if not isinstance(data, dict) or data.get("format") != SET_FORMAT:
        raise InputError(f"{path}: not a vibsynth lab stimulus set (format {SET_FORMAT!r} expected)")
    return data


def load_folder(folder: str | os.PathLike[str], *, seconds: float) -> StimulusSet:
    """A set from a folder of WAV files (mono, or the first channel), each cut to ``seconds``.

    Parameters
    ----------
    folder : path-like
    seconds : float
        Stimulus duration; the middle of each recording is kept.

    Returns
    -------
    set : StimulusSet
        Ids are the file stems (other characters than letters, digits and ``_.+-`` become
        ``_``); a folder written by the lab (with ``set.json``) is marked ``equalised``.

    Raises
    ------
    InputError
        Not a folder, no WAV files, more than :data:`MAX_STIMULI`, a file over
        :data:`MAX_WAV_BYTES`, unreadable or too short files (all of them named), two files
        giving the same id.
    """
    path = Path(folder).expanduser()
    files = _wav_files(path)
    manifest = _read_manifest(path)
    problems: list[str] = []
    stimuli: list[Stimulus] = []
    ids: dict[str, Path] = {}
    for f in files:
        try:
            size = f.stat().st_size
            if size > MAX_WAV_BYTES:
                raise InputError(size_limit_message(f.name, size, MAX_WAV_BYTES, "a stimulus"))
            rec = read_recording(f)
            samples = _middle(rec.samples, rec.fs, seconds, f.name)
        except (InputError, OSError) as exc:
            problems.append(str(exc).replace(f"{f}:", f"{f.name}:"))
            continue
        sid = stimulus_id(f.stem)
        if sid in ids:
            raise InputError(f"{path}: {ids[sid].name} and {f.name} give the same stimulus id {sid!r}; rename one")
        ids[sid] = f
        stimuli.append(Stimulus(sid, samples, rec.fs, {"source": "file", "file": str(f.resolve())}))
    if problems:
        more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
        raise InputError(f"{path}: {len(problems)} WAV file(s) cannot be used: {'; '.join(problems[:3])}{more}")
    return StimulusSet(str(path), "folder", tuple(stimuli), equalised=bool(manifest and manifest.get("equalised")))


def _render_texture(
    shaper: SpectralShaper, basis: Basis, balance: float, level_db: float, rng: np.random.Generator
) -> NDArray[np.float64]:
    weights = shaper.solve_balance(basis, balance, level_db=level_db)
    return np.asarray(shaper.render(shaper.power_envelope(weights), shaper.random_phases(rng)), dtype=np.float64)


def load_presets(
    presets: Sequence[Preset],
    *,
    fs: float,
    seconds: float,
    seed: int,
    basis: Basis,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
    name: str = "presets",
) -> StimulusSet:
    """Presets rendered as the engine plays them: ``M + t1(balance) V1`` at the intensity's level.

    Parameters
    ----------
    presets : sequence of Preset
    fs : float
        Rate to render at (the engine's).
    seconds : float
    seed : int
        Seeds the random phases (same seed, same samples).
    basis : Basis
    ceiling_db, range_db : float
        The intensity knob mapping (``knobs.ceiling_db``, ``knobs.range_db``).
    name : str
        The set's name.

    Raises
    ------
    InputError
        No presets, more than :data:`MAX_STIMULI`, or a preset with intensity 0 (silence).
    """
    if not presets:
        raise InputError("no presets to make stimuli of")
    if len(presets) > MAX_STIMULI:
        raise InputError(f"{len(presets)} presets; a set has at most {MAX_STIMULI} stimuli (name fewer: presets:a,b)")
    shaper = SpectralShaper(
        fs=fs, n_samples=int(round(seconds * fs)), centres=basis.centres_hz, order=basis.filter_order
    )
    rng = np.random.default_rng([seed, PHASES_STREAM])
    stimuli = []
    for preset in presets:
        if preset.intensity <= 0:
            raise InputError(f"preset {preset.name!r} has intensity 0 (silence): it cannot be a stimulus")
        level = knob_to_level_db(preset.intensity, ceiling_db=ceiling_db, range_db=range_db)
        samples = _render_texture(shaper, basis, preset.balance, level, rng)
        params = {"source": "preset", "preset": preset.name, "intensity": preset.intensity, "balance": preset.balance}
        stimuli.append(Stimulus(stimulus_id(preset.name), samples, float(fs), params))
    return StimulusSet(name, "presets", tuple(stimuli))


def load_renders(
    count: int,
    *,
    fs: float,
    seconds: float,
    seed: int,
    basis: Basis,
    intensity: float = 0.75,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
) -> StimulusSet:
    """The engine's textures on a balance grid: ``count`` balances from -1 to +1, one intensity.

    Every stimulus has the same 80-200 Hz level (iso-intense by the paper's model) and a known
    t1, which makes the set a calibration of the method itself.

    Parameters
    ----------
    count : int
        2 .. :data:`MAX_STIMULI`.
    fs, seconds, seed, basis, ceiling_db, range_db
        As :func:`load_presets`.
    intensity : float
        Knob value of every stimulus.
    """
    if not 2 <= count <= MAX_STIMULI:
        raise ParameterError(f"renders: the count must be 2..{MAX_STIMULI}, got {count}")
    shaper = SpectralShaper(
        fs=fs, n_samples=int(round(seconds * fs)), centres=basis.centres_hz, order=basis.filter_order
    )
    rng = np.random.default_rng([seed, PHASES_STREAM])
    level = knob_to_level_db(intensity, ceiling_db=ceiling_db, range_db=range_db)
    stimuli = []
    width = len(str(count))
    for i, balance in enumerate(np.linspace(*RENDERS_BALANCE_SPAN, count)):
        samples = _render_texture(shaper, basis, float(balance), level, rng)
        params = {"source": "render", "intensity": intensity, "balance": round(float(balance), 6)}
        stimuli.append(Stimulus(f"render-{i + 1:0{width}d}", samples, float(fs), params))
    return StimulusSet(f"renders:{count}", "renders", tuple(stimuli))


def load_set(
    spec: str | SetSpec,
    *,
    presets: Callable[[], Iterable[Preset]],
    fs: float,
    seconds: float,
    seed: int,
    basis: Basis,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
    render_intensity: float = 0.75,
) -> StimulusSet:
    """Load the set a spec names (see :func:`parse_set_spec`).

    Parameters
    ----------
    spec : str or SetSpec
    presets : callable
        Returns the preset library's presets (shipped + user), read only when a spec names presets.
    fs : float
        Rate of presets and renders (the engine's); files keep their own rate.
    seconds, seed, basis, ceiling_db, range_db, render_intensity
        As the loaders.

    Raises
    ------
    InputError
        The folder or a preset cannot be used (unknown preset names are listed).
    """
    parsed = parse_set_spec(spec) if isinstance(spec, str) else spec
    if parsed.kind == "sines":
        return load_sines(parsed.freqs, fs=fs, seconds=seconds)
    if parsed.kind == "folder":
        assert parsed.folder is not None
        return load_folder(parsed.folder, seconds=seconds)
    if parsed.kind == "renders":
        return load_renders(
            parsed.count,
            fs=fs,
            seconds=seconds,
            seed=seed,
            basis=basis,
            intensity=render_intensity,
            ceiling_db=ceiling_db,
            range_db=range_db,
        )
    library = {p.name: p for p in presets()}
    if parsed.names:
        unknown = [n for n in parsed.names if n not in library]
        if unknown:
            raise InputError(f"unknown preset(s): {', '.join(unknown)} (known: {', '.join(sorted(library)) or 'none'})")
        if len(set(parsed.names)) != len(parsed.names):
            raise InputError(f"stimulus set {parsed.text}: a preset is named twice")
        chosen = [library[n] for n in parsed.names]
    else:
        chosen = [library[n] for n in sorted(library)]
    return load_presets(
        chosen,
        fs=fs,
        seconds=seconds,
        seed=seed,
        basis=basis,
        ceiling_db=ceiling_db,
        range_db=range_db,
        name=parsed.text,
    )


# --------------------------------------------------------------------------- preparing
def prepare(stimulus_set: StimulusSet, *, mode: Normalise, level_db: float, basis: Basis) -> StimulusSet:
    """Normalise each stimulus, then scale the set so its median stimulus is at ``level_db``.

    Parameters
    ----------
    stimulus_set : StimulusSet
    mode : {"std", "band", "none"}
        Per-stimulus normalisation (see the module docstring).
    level_db : float
        80-200 Hz band level of the set's median stimulus after preparation.
    basis : Basis

    Returns
    -------
    set : StimulusSet
        Each stimulus' params gain ``normalise``, ``gain_applied`` (linear factor from its
        source) and what :func:`measure` gives of the prepared samples.

    Raises
    ------
    InputError
        A stimulus is silent or cannot be analysed (named).
    ParameterError
        Unknown mode, non-finite level.
    """
    if mode not in NORMALISE_MODES:
        raise ParameterError(f"unknown normalisation {mode!r}; choose one of {', '.join(NORMALISE_MODES)}")
    if not math.isfinite(level_db):
        raise ParameterError(f"level must be finite, got {level_db}")
    measured, gains = [], []
    for s in stimulus_set.stimuli:
        try:
            m = measure(s.samples, s.fs, basis)
        except ParameterError as exc:
            raise InputError(f"stimulus {s.id}: {exc}") from None
        if mode == "std":
            gain = 1.0 / m["rms"]
        elif mode == "band":
            gain = 10.0 ** (-m["level_db"] / 20.0)
        else:
            gain = 1.0
        measured.append(m)
        gains.append(gain)
    levels = [m["level_db"] + 20.0 * math.log10(g) for m, g in zip(measured, gains)]
    common = 10.0 ** ((level_db - float(np.median(levels))) / 20.0)
    out = []
    for s, m, gain in zip(stimulus_set.stimuli, measured, gains):
        total = gain * common
        db = 20.0 * math.log10(total)
        params = dict(s.params)
        params.update(m)  # a gain moves the levels by its dB and the amplitudes by itself; shape and t1 stay
        params.update(
            {
                "normalise": mode,
                "gain_applied": total,
                "level_db": round(m["level_db"] + db, 4),
                "broadband_db": round(m["broadband_db"] + db, 4),
                "rms": m["rms"] * total,
                "peak": m["peak"] * total,
            }
        )
        out.append(replace(s, samples=s.samples * total, params=params))
    return replace(stimulus_set, stimuli=tuple(out))


def resampled(samples: NDArray[np.float64], fs_from: float, fs_to: float) -> NDArray[np.float64]:
    """Band-limited resampling (polyphase; rates rounded to whole Hz).

    Parameters
    ----------
    samples : ndarray, shape (n_samples,)
    fs_from, fs_to : float

    Returns
    -------
    samples : ndarray, shape (round(n_samples * fs_to / fs_from),)
    """
    from scipy.signal import resample_poly

    a, b = int(round(fs_from)), int(round(fs_to))
    if a <= 0 or b <= 0:
        raise ParameterError(f"sample rates must be positive, got {fs_from} and {fs_to}")
    if a == b:
        return np.asarray(samples, dtype=np.float64)
    ratio = Fraction(b, a).limit_denominator(10_000)
    out = resample_poly(np.asarray(samples, dtype=np.float64), ratio.numerator, ratio.denominator)
    n = int(round(samples.size * b / a))
    return np.asarray(out[:n] if out.size >= n else np.pad(out, (0, n - out.size)), dtype=np.float64)


def reference_noise(
    stimuli: Sequence[Stimulus], *, seconds: float, seed: int, basis: Basis, match: str = "level"
) -> Stimulus:
    """The intensity reference: white noise (flat to 1400 Hz, as the paper's at 2800 Hz).

    Parameters
    ----------
    stimuli : sequence of Stimulus
        Prepared stimuli (:func:`prepare`); the noise is made at the rate of the first.
    seconds : float
    seed : int
        The session's seed (the noise is drawn from a stream of its own).
    basis : Basis
    match : {"level", "std"}
        ``"level"`` (default): scaled to the stimuli's median 80-200 Hz level, so the gains a
        participant needs fall inside 0.2-5 (they are the stimuli's band-level differences);
        ``"std"``: the stimuli's median standard deviation (the paper's reference, a white
        noise of the same standard deviation as the std-equalised stimuli).

    Returns
    -------
    reference : Stimulus
        Id ``reference``; its params say how it was made and what it measures.
    """
    if not stimuli:
        raise ParameterError("no stimuli to match a reference to")
    fs = stimuli[0].fs
    rng = np.random.default_rng([seed, REFERENCE_STREAM])
    base = rng.standard_normal(int(round(seconds * REFERENCE_RATE_HZ)))
    noise = resampled(base, REFERENCE_RATE_HZ, fs)
    if match == "level":
        target = float(np.median([s.params["level_db"] for s in stimuli]))
        noise *= 10.0 ** ((target - measure(noise, fs, basis)["level_db"]) / 20.0)
    elif match == "std":
        noise *= float(np.median([s.params["rms"] for s in stimuli])) / float(np.sqrt(np.mean(noise**2)))
    else:
        raise ParameterError(f"reference match must be 'level' or 'std', got {match!r}")
    params: dict[str, Any] = {"source": "white noise", "bandwidth_hz": REFERENCE_RATE_HZ / 2, "match": match}
    params.update(measure(noise, fs, basis))
    return Stimulus("reference", noise, fs, params)


def resynthesis_versions(original: Stimulus, *, basis: Basis, seed: int, index: int = 0) -> dict[str, Stimulus]:
    """Experiment 3's five versions of an original (see :data:`~vibsynth.research.lab.protocol.VERSIONS`).

    The synthesised versions are noise with the variant's 30-band spectrum at the original's
    80-200 Hz level (closed-form synthesis, :class:`~vibsynth.dsp.synthesis.SpectralShaper`),
    as long as the original, at its rate.

    Parameters
    ----------
    original : Stimulus
        A prepared stimulus.
    basis : Basis
    seed : int
        The session's seed; with ``index`` it seeds the random phases.
    index : int
        The original's position in its set (each original gets phases of its own).

    Returns
    -------
    versions : dict of str to Stimulus
        ``"O"`` is the original itself; the others have ids ``<original>.S1``, ``.S1-8``,
        ``.S2-8``, ``.M`` and params ``version``, ``original`` and their measures.
    """
    try:
        analysis = analyze(original.samples, fs=original.fs, basis=basis)
    except ParameterError as exc:
        raise InputError(f"stimulus {original.id}: {exc}") from None
    spectra = variant_spectra(analysis, basis)
    shaper = SpectralShaper(
        fs=original.fs, n_samples=original.samples.size, centres=basis.centres_hz, order=basis.filter_order
    )
    rng = np.random.default_rng([seed, VERSIONS_STREAM, index])
    out = {"O": original}
    for version in VERSIONS[1:]:
        weights = shaper.solve_weights(spectra[version], level_db=analysis.level_db)
        samples = np.asarray(shaper.render(shaper.power_envelope(weights), shaper.random_phases(rng)), dtype=np.float64)
        params: dict[str, Any] = {"source": "resynthesis", "version": version, "original": original.id}
        params.update(measure(samples, original.fs, basis))
        out[version] = Stimulus(f"{original.id}.{VERSION_TAGS[version]}", samples, original.fs, params)
    return out
