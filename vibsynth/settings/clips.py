"""Haptic clips: timelines of the two knobs (intensity, balance) in hand-editable YAML files.

Schema (version 1; every key in ``docs/clips.md``)::

    version: 1                  # optional
    name: heartbeat             # = the file name without .yaml (optional)
    description: Resting pulse  # free text (optional)
    tags: [body, loop]          # optional
    duration_ms: 1000           # > 0, at most 10 minutes
    loop: {start_ms: 0, end_ms: 1000}   # optional loop points, start < end <= duration
    keyframes:                  # 1..MAX_KEYFRAMES, t_ms strictly increasing, <= duration_ms
      - {t_ms: 0, intensity: 0.1, balance: -1.0}                 # interp: linear (default)
      - {t_ms: 120, intensity: 0.3, balance: -1.0, interp: smooth}
      - {t_ms: 500, intensity: 0.1, balance: -1.0, interp: hold}
    transients:                 # optional short bursts on top of the curve
      - {t_ms: 0, intensity: 0.9, balance: -1.5, decay_ms: 60}

``interp`` is the shape of the segment that *starts* at its keyframe. Before the first keyframe
and after the last, the curve holds their values. Every error names the file, the line, the key,
the value and the allowed range (:class:`~vibsynth.settings.validation.InvalidClipError`, with
``.problems``). :class:`ClipLibrary` merges the shipped clips (``vibsynth/data/clips``) with the
user's folder (``clips.user_dir``) and is hot reloaded by :class:`ClipWatcher`, exactly like presets.
"""

from __future__ import annotations

import math
import os
from bisect import bisect_right
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from vibsynth.errors import ClipError
from vibsynth.formats.files import MAX_YAML_BYTES
from vibsynth.settings.fields import show
from vibsynth.settings.library import FileLibrary, LibraryKind, shipped_dir, user_dir_of
from vibsynth.settings.models_clip import CLIP_VERSION, ClipModel
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.reload import LibraryWatcher
from vibsynth.settings.validation import InvalidClipError, model_spec, validate
from vibsynth.settings.yamldoc import (
    SUFFIX,
    YamlDocument,
    dump_block,
    file_stem,
    parse_yaml,
    read_yaml_file,
    write_checked,
)

__all__ = [
    "WHAT",
    "MAX_CLIP_BYTES",
    "Keyframe",
    "Transient",
    "Clip",
    "InvalidClipError",
    "UnknownClipError",
    "parse_clip",
    "clip_from_data",
    "load_clip",
    "clip_to_yaml",
    "save_clip",
    "CLIPS",
    "ClipLibrary",
    "ClipWatcher",
    "shipped_clips_dir",
    "load_clip_library",
]

WHAT = "a clip"
#: Clip files over this size are never read (a hand-made clip is 1-5 KB; 4096 keyframes ~ 250 KB).
MAX_CLIP_BYTES = MAX_YAML_BYTES


class UnknownClipError(ClipError):
    """No clip (valid or broken) has this name: for a name typed on a command line, a usage error."""


@dataclass(frozen=True)
class Keyframe:
    """A point of the knob curve.

    Attributes
    ----------
    t_ms : float
        Time from the clip's start.
    intensity : float
        Knob 0..1.
    balance : float
        Knob units.
    interp : str
        ``"linear"``, ``"hold"`` or ``"smooth"``: the shape of the segment from this keyframe to the next.
    """

    t_ms: float
    intensity: float
    balance: float
    interp: str = "linear"


@dataclass(frozen=True)
class Transient:
    """A short burst on top of the curve.

    Attributes
    ----------
    t_ms : float
        Onset.
    intensity : float
        Peak knob 0..1.
    balance : float
        Knob units.
    decay_ms : float
        Time for the burst to die away, (0, 2000].
    """

    t_ms: float
    intensity: float
    balance: float
    decay_ms: float


def _ease(u: float, interp: str) -> float:
    """Weight of the next keyframe at fraction ``u`` in [0, 1] of a segment."""
    if interp == "hold":
        return 0.0
    if interp == "smooth":
        return 0.5 - 0.5 * math.cos(math.pi * u)
    return u


@dataclass(frozen=True)
class Clip:
    """A haptic clip: a knob curve over ``duration_ms`` plus transients and loop points.

    Attributes
    ----------
    name : str
    duration_ms : float
    keyframes : tuple of Keyframe
        At least one, ``t_ms`` strictly increasing, all within the duration.
    transients : tuple of Transient
        Sorted by ``t_ms``.
    loop : (float, float) or None
        ``(start_ms, end_ms)`` loop points, ``start < end <= duration_ms``.
    tags : tuple of str
    description : str
    path : pathlib.Path or None
        File it was loaded from (not part of equality).
    origin : str
        ``"shipped"``, ``"user"`` or ``""`` (not part of equality).
    """

    name: str
    duration_ms: float
    keyframes: tuple[Keyframe, ...]
    transients: tuple[Transient, ...] = ()
    loop: tuple[float, float] | None = None
    tags: tuple[str, ...] = ()
    description: str = ""
    path: Path | None = field(default=None, compare=False)
    origin: str = field(default="", compare=False)

    def value_at(self, t_ms: float) -> tuple[float, float]:
        """The curve (without transients) at a time: ``(intensity, balance)``.

        Before the first keyframe and after the last, their values hold. Inside a segment the
        first keyframe's ``interp`` applies: ``linear`` ramps, ``hold`` keeps the first value up
        to the next keyframe, ``smooth`` is a cosine ease (zero slope at both keyframes).
        """
        keys = self.keyframes
        i = bisect_right(keys, t_ms, key=lambda k: k.t_ms) - 1
        if i < 0:
            return keys[0].intensity, keys[0].balance
        if i >= len(keys) - 1:
            return keys[-1].intensity, keys[-1].balance
        a, b = keys[i], keys[i + 1]
        w = _ease((t_ms - a.t_ms) / (b.t_ms - a.t_ms), a.interp)
        return a.intensity + w * (b.intensity - a.intensity), a.balance + w * (b.balance - a.balance)

    def values_at(self, times_ms: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The curve at many times at once (vectorised :meth:`value_at`).

        Parameters
        ----------
        times_ms : array_like, shape (n,)

        Returns
        -------
        values : ndarray, shape (n, 2)
            Column 0 intensity, column 1 balance.
        """
        t = np.asarray(times_ms, dtype=np.float64).reshape(-1)
        keys = self.keyframes
        kt = np.array([k.t_ms for k in keys])
        kv = np.array([[k.intensity, k.balance] for k in keys])
        out = np.empty((t.size, 2))
        i = np.searchsorted(kt, t, side="right") - 1
        before, after = i < 0, i >= len(keys) - 1
        out[before] = kv[0]
        out[after] = kv[-1]
        inside = ~(before | after)
        j = i[inside]
        u = (t[inside] - kt[j]) / (kt[j + 1] - kt[j])
        kinds = np.array([k.interp for k in keys])[j]
        w = np.where(kinds == "hold", 0.0, np.where(kinds == "smooth", 0.5 - 0.5 * np.cos(np.pi * u), u))
        out[inside] = kv[j] + w[:, None] * (kv[j + 1] - kv[j])
        return out

    def to_dict(self) -> dict[str, Any]:
        """Plain data in file order (optional keys left out when empty, ``interp`` when linear)."""
        out: dict[str, Any] = {"version": CLIP_VERSION, "name": self.name}
        if self.description:
            out["description"] = self.description
        if self.tags:
            out["tags"] = list(self.tags)
        out["duration_ms"] = _num(self.duration_ms)
        if self.loop is not None:
            out["loop"] = {"start_ms": _num(self.loop[0]), "end_ms": _num(self.loop[1])}
        out["keyframes"] = [_keyframe_dict(k) for k in self.keyframes]
        if self.transients:
            out["transients"] = [
                {
                    "t_ms": _num(t.t_ms),
                    "intensity": _num(t.intensity),
                    "balance": _num(t.balance),
                    "decay_ms": _num(t.decay_ms),
                }
                for t in self.transients
            ]
        return out


def _keyframe_dict(k: Keyframe) -> dict[str, Any]:
    out: dict[str, Any] = {"t_ms": _num(k.t_ms), "intensity": _num(k.intensity), "balance": _num(k.balance)}
    if k.interp != "linear":
        out["interp"] = k.interp
    return out


def _num(x: float) -> float | int:
    """A number as a person would write it: 120 rather than 120.0, at most 6 decimals."""
    x = round(float(x), 6)
    return int(x) if x.is_integer() and abs(x) < 1e15 else x


# --------------------------------------------------------------------------- reading
def clip_from_data(data: Any, locate: Any, stem: str | None) -> Clip:
    """Validate plain data (a parsed file, an import, the studio's editor) into a :class:`Clip`.

    Parameters
    ----------
    data : Any
        The mapping of a clip file.
    locate : Locator
        Where each key came from (a :class:`~vibsynth.settings.yamldoc.YamlDocument`, or a
        :class:`~vibsynth.settings.validation.FixedLocator`).
    stem : str or None
        The file name without ``.yaml``: the clip's name (a ``name`` key must match it).

    Raises
    ------
    InvalidClipError
        Every schema problem (``.problems``), the first in file order as the message.
    ClipError
        Not a mapping, no name, a name that does not match the file.
    """
    spec = model_spec(ClipModel)
    if not isinstance(data, dict):
        raise ClipError(
            f"{locate.where(())}: a clip must be a mapping of keys ({', '.join(spec.sections[''])}), got {show(data)}"
        )
    model: ClipModel = validate(spec, data, locate, ClipError)
    name = model.name if model.name is not None else stem
    if name is None:
        raise ClipError(f"{locate.where(())}: missing key 'name'")
    if stem is not None and name != stem:
        raise ClipError(
            f"{locate.where(('name',))}: name = {name!r} does not match the file name {stem}{SUFFIX} "
            "(rename the file or change the name)"
        )
    return Clip(
        name=name,
        duration_ms=float(model.duration_ms),
        keyframes=tuple(
            Keyframe(float(k.t_ms), float(k.intensity), float(k.balance), k.interp) for k in model.keyframes
        ),
        transients=tuple(
            sorted(
                (
                    Transient(float(t.t_ms), float(t.intensity), float(t.balance), float(t.decay_ms))
                    for t in model.transients
                ),
                key=lambda t: t.t_ms,
            )
        ),
        loop=None if model.loop is None else (float(model.loop.start_ms), float(model.loop.end_ms)),
        tags=tuple(model.tags or ()),
        description=model.description.strip(),
    )


def _from_document(doc: YamlDocument, stem: str | None) -> Clip:
    if doc.data is None:
        raise ClipError(f"{doc.origin}: the file is empty (a clip needs at least duration_ms and keyframes)")
    return clip_from_data(doc.data, doc, stem)


def parse_clip(text: str, origin: str = "<clip>", *, name: str | None = None) -> Clip:
    """Parse and validate clip YAML text.

    Parameters
    ----------
    text : str
    origin : str
        File name for messages.
    name : str, optional
        Expected name (the file stem); the ``name`` key may then be omitted.

    Raises
    ------
    ClipError
        Syntax error, duplicate or unknown key, wrong type, out-of-range value, times out of
        order (:class:`InvalidClipError` for schema problems).
    """
    return _from_document(parse_yaml(text, origin, error=ClipError, what=WHAT), name)


def load_clip(path: str | os.PathLike[str], *, origin: str = "") -> Clip:
    """Read and validate a clip file (its name is the file name without ``.yaml``).

    Files over :data:`MAX_CLIP_BYTES` are refused before they are read; YAML aliases and
    deep nesting are refused (see :func:`vibsynth.formats.yamlio.load_yaml`).
    """
    p = Path(path)
    doc = read_yaml_file(p, error=ClipError, what=WHAT)
    return replace(_from_document(doc, file_stem(p)), path=p, origin=origin)


# --------------------------------------------------------------------------- writing
_HEADER = "# vibsynth haptic clip (schema: docs/clips.md). Edit freely; saved atomically.\n"


def clip_to_yaml(clip: Clip, *, header: str = _HEADER) -> str:
    """YAML text of a clip: keys in schema order, one keyframe or transient per line."""
    return header + dump_block(clip.to_dict())


def save_clip(clip: Clip, path: str | os.PathLike[str] | None = None, *, header: str = _HEADER) -> Path:
    """Validate and write a clip atomically; returns the path.

    Parameters
    ----------
    clip : Clip
    path : path-like, optional
        Default: ``clip.path``. The file name must be ``<name>.yaml``.
    """
    target = Path(path) if path is not None else clip.path
    if target is None:
        raise ClipError(f"clip {clip.name!r}: no file to save to")
    return write_checked(target, clip_to_yaml(clip, header=header), _parse_named, ClipError)


def _parse_named(text: str, origin: str, name: str) -> Clip:
    return parse_clip(text, origin, name=name)


# --------------------------------------------------------------------------- the library
#: Clips as a kind of library file (see :class:`~vibsynth.settings.library.FileLibrary`).
CLIPS: LibraryKind[Clip] = LibraryKind(
    noun="clip",
    what=WHAT,
    folder="clips",
    section="clips",
    load=load_clip,
    save=save_clip,
    error=ClipError,
    unknown=UnknownClipError,
    max_bytes=MAX_CLIP_BYTES,
)


def shipped_clips_dir() -> Path:
    """Folder of the clips shipped as package data (``vibsynth/data/clips``)."""
    return shipped_dir(CLIPS.folder)


class ClipLibrary(FileLibrary[Clip]):
    """Shipped clips plus a user folder; a user clip overrides a shipped one of the same name.

    Parameters
    ----------
    shipped_dir : path-like or None
        Default: :func:`shipped_clips_dir`. None = no shipped clips (tests).
    user_dir : path-like or None
        User clips (need not exist yet).
    load : bool
        Read the folders now.

    Notes
    -----
    The same folder handling as presets (:class:`~vibsynth.settings.library.FileLibrary`):
    broken files are skipped with one warning each (their last good version stays in use),
    :meth:`get` raises :class:`UnknownClipError` with close names, :meth:`reload` re-reads
    only files whose (mtime, size, inode) changed.
    """

    kind = CLIPS

    def clips(self) -> list[Clip]:
        """Every effective clip, sorted by name."""
        return self.items()


#: The clip library's hot reload: ``ClipWatcher(library, on_change).start()``.
ClipWatcher = LibraryWatcher


def load_clip_library(settings: VibsynthConfig | None = None) -> ClipLibrary:
    """The clip library for the settings: shipped clips + ``clips.user_dir`` (or the platform folder's ``clips/``)."""
    return ClipLibrary(shipped_clips_dir(), user_dir_of(settings, CLIPS))
