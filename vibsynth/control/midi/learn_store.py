"""Saving learned MIDI bindings into the user's config file, keeping its comments and order."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from vibsynth.control.midi.bindings import KNOBS, Binding


def user_config_path(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The config file MIDI learn writes to.

    ``--config`` if given, else the platform config folder's ``config.yaml``.
    """
    if explicit:
        return Path(explicit)
    try:
        import platformdirs

        return Path(platformdirs.user_config_dir("vibsynth")) / "config.yaml"
    except ImportError:  # pragma: no cover - platformdirs is a dependency
        return Path.home() / ".config" / "vibsynth" / "config.yaml"


def save_learned_mapping(
    path: str | os.PathLike[str], bindings: Iterable[Binding], knobs: Iterable[str] = KNOBS
) -> None:
    """Write ``midi.mapping.<knob>`` for ``knobs`` into a YAML file, keeping its comments and other keys.

    Uses ruamel.yaml round-trip mode through :func:`vibsynth.formats.yamlio.load_yaml` (the one YAML
    loader: size cap, no aliases, bounded nesting); the file (and its folder) is created
    when missing; the write goes through :func:`vibsynth.formats.files.atomic_write` (a crash leaves
    the old file or the new one; the file keeps its mode). Bindings that come from
    ``midi.nrpn`` shorthand keys are written as ``{nrpn: [msb, lsb]}`` entries only if
    they were learned.

    Parameters
    ----------
    path : path
    bindings : iterable of Binding
        The full current bindings.
    knobs : iterable of str
        Knobs whose lists are (re)written.

    Raises
    ------
    ConfigError
        The existing file is over the size cap, holds a YAML alias or a syntax error
        (named by file and line; nothing is written).
    OSError
        The file cannot be written (the old one is untouched).
    """
    import io as _io

    from ruamel.yaml import YAML
    from ruamel.yaml.comments import CommentedMap, CommentedSeq

    from vibsynth.errors import ConfigError
    from vibsynth.formats.files import atomic_write
    from vibsynth.formats.yamlio import load_yaml

    path = Path(path)
    doc = None
    if path.exists():
        doc = load_yaml(path, round_trip=True, error=ConfigError, what="a config file").data
    if doc is None:
        doc = CommentedMap()
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: the config must be a mapping of sections, not {type(doc).__name__}")
    midi = doc.get("midi")
    if midi is None:
        midi = doc["midi"] = CommentedMap()
    mapping = midi.get("mapping")
    if mapping is None:
        mapping = midi["mapping"] = CommentedMap()
    bindings = list(bindings)
    for knob in knobs:
        entries = CommentedSeq()
        for b in bindings:
            if b.knob == knob and (b.cc is not None or b.nrpn is not None):
                item = CommentedMap(b.to_config())
                item.fa.set_flow_style()
                entries.append(item)
        entries.fa.set_flow_style()
        mapping[knob] = entries
    text = _io.StringIO()
    YAML().dump(doc, text)  # round-trip dumper: comments and layout kept
    atomic_write(path, text.getvalue())
