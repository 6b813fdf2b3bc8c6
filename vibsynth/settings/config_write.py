"""Writing a setting into the user's config file, keeping its comments, order and other keys.

The service writes its config in two places: MIDI learn (``midi.mapping``,
:mod:`vibsynth.control.midi.learn_store`) and the studio's calibrate tab ("apply to channel":
``actuator.channel_profiles``). Both write the file the config layer reads as the user's
(:func:`user_config_path`), through the one YAML loader (size cap, no aliases, bounded nesting)
in ruamel.yaml's round-trip mode, and atomically.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vibsynth.errors import ConfigError
from vibsynth.settings.config import CONFIG_ENV_VAR, user_config_file

__all__ = ["user_config_path", "load_round_trip", "dump_round_trip", "write_config_key"]


def user_config_path(explicit: str | os.PathLike[str] | None = None, env: Mapping[str, str] | None = None) -> Path:
    """The config file the service writes to: the file the config layer reads as the user's.

    The rule of :func:`vibsynth.settings.config.load_config`: ``--config`` if given, else
    ``$VIBSYNTH_CONFIG`` if set and not empty, else the platform file
    (:func:`vibsynth.settings.config.user_config_file`), which is created when missing.

    Parameters
    ----------
    explicit : path-like, optional
        The ``--config`` argument.
    env : mapping, optional
        Environment (default ``os.environ``).

    Returns
    -------
    path : Path
    """
    env = os.environ if env is None else env
    if explicit:
        return Path(explicit).expanduser()
    if env.get(CONFIG_ENV_VAR):
        return Path(env[CONFIG_ENV_VAR]).expanduser()
    return user_config_file()


def load_round_trip(path: Path) -> Any:
    """The config file as a round-trip mapping (an empty one when the file is missing or empty).

    Raises
    ------
    ConfigError
        Over the size cap, a YAML alias, a syntax error (file and line), or not a mapping.
    """
    from ruamel.yaml.comments import CommentedMap

    from vibsynth.formats.yamlio import load_yaml

    doc = None
    if path.exists():
        doc = load_yaml(path, round_trip=True, error=ConfigError, what="a config file").data
    if doc is None:
        doc = CommentedMap()
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: the config must be a mapping of sections, not {type(doc).__name__}")
    return doc


def dump_round_trip(path: Path, doc: Any) -> None:
    """Write a round-trip mapping back atomically (comments and layout kept; the file keeps its mode)."""
    from ruamel.yaml import YAML

    from vibsynth.formats.files import atomic_write

    text = io.StringIO()
    YAML().dump(doc, text)
    atomic_write(path, text.getvalue())


def write_config_key(path: str | os.PathLike[str], key: str, value: Any) -> Path:
    """Set one dotted key (``actuator.channel_profiles``) in a config file; every other line stays.

    A list is written in flow style (``[a, b, null]``); missing sections are added at the end.

    Raises
    ------
    ConfigError
        The file cannot be read as a config (nothing is written), or a section on the way is
        not a mapping.
    OSError
        The file cannot be written (the old one is untouched).
    """
    from ruamel.yaml.comments import CommentedMap, CommentedSeq

    path = Path(path)
    doc = load_round_trip(path)
    *sections, leaf = key.split(".")
    node = doc
    for i, name in enumerate(sections):
        child = node.get(name)
        if child is None:
            child = node[name] = CommentedMap()
        if not isinstance(child, dict):
            where = ".".join(sections[: i + 1])
            raise ConfigError(f"{path}: {where} must be a mapping to hold {key}, not {type(child).__name__}")
        node = child
    if isinstance(value, list | tuple):
        seq = CommentedSeq(list(value))
        seq.fa.set_flow_style()
        value = seq
    node[leaf] = value
    dump_round_trip(path, doc)
    return path
