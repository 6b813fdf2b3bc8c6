"""Saving learned MIDI bindings into the user's config file, keeping its comments and order."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from vibsynth.control.midi.bindings import DEFAULT_NRPN, KNOBS, OPTIONAL_KNOBS, Binding
from vibsynth.settings.config_write import dump_round_trip, load_round_trip

__all__ = ["save_learned_mapping"]


def save_learned_mapping(
    path: str | os.PathLike[str], bindings: Iterable[Binding], knobs: Iterable[str] = KNOBS
) -> None:
    """Write ``midi.mapping.<knob>`` for ``knobs`` into a YAML file, keeping its comments and other keys.

    Uses ruamel.yaml round-trip mode through :func:`vibsynth.formats.yamlio.load_yaml` (the one YAML
    loader: size cap, no aliases, bounded nesting); the file (and its folder) is created
    when missing; the write goes through :func:`vibsynth.formats.files.atomic_write` (a crash leaves
    the old file or the new one; the file keeps its mode). Bindings that come from
    ``midi.nrpn`` shorthand keys are written as ``{nrpn: [msb, lsb]}`` entries only if
    they were learned. A shorthand binding that is no longer in ``bindings`` (a learned
    binding took its controller) is removed from ``midi.nrpn`` (written with the remaining
    ones when the file had no such key), so the file reloads into the same bindings.

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
    from ruamel.yaml.comments import CommentedMap, CommentedSeq

    path = Path(path)
    doc = load_round_trip(path)
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
            if b.knob == knob and not b.shorthand and (b.cc is not None or b.nrpn is not None):
                item = CommentedMap(b.to_config())
                item.fa.set_flow_style()
                entries.append(item)
        if not entries and knob in OPTIONAL_KNOBS and knob not in mapping:
            continue  # nothing bound and nothing to override: the file stays as it was
        entries.fa.set_flow_style()
        mapping[knob] = entries
    _drop_displaced_shorthand(midi, bindings)
    dump_round_trip(path, doc)


def _drop_displaced_shorthand(midi: Any, bindings: list[Binding]) -> None:
    """Remove from ``midi.nrpn`` (round-trip map) the shorthand bindings ``bindings`` no longer has."""
    from ruamel.yaml.comments import CommentedMap, CommentedSeq

    kept = {b.knob: b.nrpn for b in bindings if b.shorthand and b.nrpn is not None}
    table = midi.get("nrpn")
    configured = DEFAULT_NRPN if table is None else table
    if not isinstance(configured, Mapping):
        return  # not a mapping: the config layer reports it
    displaced = [knob for knob, number in configured.items() if number is not None and knob not in kept]
    if not displaced:
        return
    if table is None:  # the defaults apply as a whole: write the ones that remain
        table = midi["nrpn"] = CommentedMap()
        for knob, number in kept.items():
            pair = CommentedSeq([number // 128, number % 128])
            pair.fa.set_flow_style()
            table[knob] = pair
        table.fa.set_flow_style()
    else:
        for knob in displaced:
            del table[knob]
