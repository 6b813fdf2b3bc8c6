"""Configuration: layered YAML, validated by the typed model, with the origin of every value.

Layers, lowest first (a later layer overrides single keys of an earlier one):

1. built-in defaults: the package file ``vibsynth/data/config/default.yaml``
   (``config/default.yaml`` at the repository root is a symlink to it: one source);
2. the user config file: ``path`` (``--config``), else ``$VIBSYNTH_CONFIG``, else
   ``config.yaml`` in the platform config folder (see :func:`user_config_file`), if it exists;
3. environment variables for per-run settings (:data:`ENV_VARS`);
4. command-line overrides (``overrides``: nested or dotted keys).

Every key is defined once, in :class:`~vibsynth.settings.models_config.VibsynthConfig`
(type, range, allowed values, default, help). Each layer is checked against it as it is
added (unknown keys are errors), then the rules between keys on the result. Errors raise
:class:`~vibsynth.settings.validation.InvalidConfigError` (a
:class:`~vibsynth.errors.ConfigError`) with a message naming the file, the line, the key, the
value and what is allowed, e.g.::

    my.yaml:7: audio.rate = 100: outside the allowed range [2400, 384000] Hz

and every problem found, structured, in ``.problems``.

API contract used by the rest of the package:

* ``load_config(path=None, *, overrides=None) -> Config``
* ``settings_from_args(args, extra=...)`` / ``Config.settings``: the typed, validated model,
  built once at the edge (file, environment, flags). It is the one form the program passes
  on: each part takes its own typed section (``settings.knobs``, ``settings.midi``...).
* ``Config.data``: nested plain dict with every key of ``vibsynth/data/config/default.yaml``,
  with ``Config.section(name) -> dict``, ``Config.get("audio.rate")`` and ``Config.sources``
  (dotted key -> where its value came from): for reading and writing YAML and for
  ``vibsynth config`` only (``tests/test_settings_form.py`` keeps them inside ``settings/``).
* ``settings_of(config)``: the typed model of a plain config dict (``settings/`` and tests)
"""

from __future__ import annotations

import copy
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from vibsynth.errors import ConfigError
from vibsynth.settings.actuators import profile_problem
from vibsynth.settings.fields import show
from vibsynth.settings.layouts import layout_problem
from vibsynth.settings.models_config import CONFIG_VERSION, FILE_CHECKS, VibsynthConfig
from vibsynth.settings.paths import APP_NAME, user_config_file
from vibsynth.settings.typed import settings_of
from vibsynth.settings.validation import FixedLocator, Locator, did_you_mean, model_spec, validate
from vibsynth.settings.yamldoc import Path_, YamlDocument, parse_yaml, read_yaml_file, yaml_value

__all__ = [
    "APP_NAME",
    "CONFIG_ENV_VAR",
    "CONFIG_VERSION",
    "DEFAULT_CONFIG_RESOURCE",
    "ENV_VARS",
    "Config",
    "add_config_arguments",
    "check_config_file",
    "config_from_args",
    "default_config_data",
    "default_config_text",
    "load_config",
    "parse_override",
    "default_settings",
    "settings_from_args",
    "settings_of",
    "user_config_file",
]

DEFAULT_CONFIG_RESOURCE = "config/default.yaml"
DEFAULT_CONFIG_NAME = "vibsynth/data/" + DEFAULT_CONFIG_RESOURCE

#: Environment variables (per-run settings) -> dotted config key.
ENV_VARS: dict[str, str] = {
    "VIBSYNTH_OUTPUT": "audio.backend",
    "VIBSYNTH_DEVICE": "audio.device",
    "VIBSYNTH_HOST_API": "audio.host_api",
    "VIBSYNTH_RATE": "audio.rate",
    "VIBSYNTH_CHANNELS": "audio.channels",
    "VIBSYNTH_OSC_HOST": "osc.host",
    "VIBSYNTH_OSC_PORT": "osc.port",
    "VIBSYNTH_MIDI_PORT": "midi.port",
    "VIBSYNTH_PRESETS_DIR": "presets.user_dir",
}
#: The rules that read files a config names, checked when a config is loaded (not by ``settings_of``).
_FILE_CHECKS = (layout_problem, profile_problem)
#: Environment variable naming the user config file (``--config`` wins over it).
CONFIG_ENV_VAR = "VIBSYNTH_CONFIG"


def default_config_text() -> str:
    """Text of the built-in default config (package data)."""
    return resources.files("vibsynth.data").joinpath(DEFAULT_CONFIG_RESOURCE).read_text(encoding="utf-8")


def default_config_data() -> dict[str, Any]:
    """The built-in defaults as a nested dict."""
    data: dict[str, Any] = parse_yaml(default_config_text(), DEFAULT_CONFIG_NAME).data
    return data


def _is_leaf(dotted: str) -> bool:
    return dotted in model_spec(VibsynthConfig).leaves


def _leaves(data: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Dotted leaf keys of a nested dict, as the model defines them (unknown nested dicts are walked)."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if not _is_leaf(dotted) and isinstance(value, dict):
            out.update(_leaves(value, dotted + "."))
        else:
            out[dotted] = value
    return out


def _set(data: dict[str, Any], dotted: str, value: Any) -> None:
    node = data
    parts = dotted.split(".")
    for part in parts[:-1]:
        if not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    node[parts[-1]] = copy.deepcopy(value)


def _close(key: str) -> str:
    return did_you_mean(key, list(model_spec(VibsynthConfig).leaves))


@dataclass(frozen=True)
class _KeyLocator:
    """Errors of a layer whose keys each come from a named place (the environment variables)."""

    names: Mapping[str, str]
    fallback: str

    def where(self, path: tuple[str, ...]) -> str:
        for n in range(len(path), 0, -1):
            name = self.names.get(".".join(path[:n]))
            if name is not None:
                return name
        return self.fallback

    def line(self, path: tuple[str, ...]) -> int | None:
        return None


def _check_sections(data: Any, doc: YamlDocument, prefix: Path_ = ()) -> None:
    """The document and its sections must be mappings (an empty section, ``audio:``, is an empty mapping)."""
    sections = model_spec(VibsynthConfig).sections
    if not isinstance(data, dict):
        name = ".".join(prefix) or "the file"
        raise ConfigError(f"{doc.where(prefix)}: {name} must be a mapping of keys, got {show(data)}")
    for key, value in data.items():
        dotted = ".".join(prefix + (str(key),))
        if dotted in sections:
            if value is None:
                data[key] = {}
                continue
            _check_sections(value, doc, prefix + (str(key),))


@dataclass
class Config:
    """The effective configuration.

    Attributes
    ----------
    data : dict
        Nested plain dict with every key of the default config (as read; see ``settings``).
    sources : dict of str to str
        Dotted leaf key -> where its value came from (``file:line``, ``env VAR``, ``command line``).
    files : list of str
        Config files read, lowest layer first.
    model : VibsynthConfig or None
        The validated model (made from ``data`` on first use of :attr:`settings` when None).
    """

    data: dict[str, Any]
    sources: dict[str, str] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    model: VibsynthConfig | None = field(default=None, repr=False)

    @property
    def settings(self) -> VibsynthConfig:
        """The typed, validated settings (``config.settings.audio.rate``): what new code should read."""
        if self.model is None:
            self.model = settings_of(self.data)
        return self.model

    def section(self, name: str) -> dict[str, Any]:
        """One top-level section (e.g. ``"audio"``)."""
        try:
            section: dict[str, Any] = self.data[name]
        except KeyError:
            raise ConfigError(f"unknown config section {name!r}; sections: {', '.join(self.data)}") from None
        return section

    def get(self, dotted: str) -> Any:
        """A value by dotted key, e.g. ``config.get("osc.port")``."""
        node: Any = self.data
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                raise ConfigError(f"unknown config key {dotted!r}{_close(dotted)}")
            node = node[part]
        return node

    def leaves(self) -> dict[str, Any]:
        """Every dotted leaf key and its value, in file order."""
        return _leaves(self.data)


def _parse_env_value(name: str, text: str) -> Any:
    value = yaml_value(text, f"environment variable {name}")
    return text if isinstance(value, (dict, list)) else value


class _Layers:
    """The merged data, checked one layer at a time, and the source of every value."""

    def __init__(self) -> None:
        self.data: dict[str, Any] = {}
        self.sources: dict[str, str] = {}
        self.spec = model_spec(VibsynthConfig)

    def add(self, values: Mapping[str, Any], locate: Locator, source: Callable[[str], str]) -> None:
        """Apply dotted ``values`` and check every key (not yet the rules between keys)."""
        merged = copy.deepcopy(self.data)
        for dotted, value in values.items():
            _set(merged, dotted, value)
        validate(self.spec, merged, locate, ConfigError, context={"cross_checks": False})
        self.data = merged
        for dotted in values:
            self.sources[dotted] = source(dotted)

    def finish(self) -> VibsynthConfig:
        """Check the rules between keys, blaming the value a person set (file, env, command line)."""

        def blame(keys: Sequence[str]) -> tuple[str, Locator]:
            chosen = next((k for k in keys if not self.sources.get(k, "default").startswith("default")), keys[0])
            return chosen, FixedLocator(self.sources.get(chosen, "config"))

        model: VibsynthConfig = validate(
            self.spec, self.data, FixedLocator("config"), ConfigError, context={FILE_CHECKS: _FILE_CHECKS}, blame=blame
        )
        for dotted in self.spec.leaves:  # values the model reads differently (audio.backend: null is "null")
            parts = dotted.split(".")
            node: Any = self.data
            for part in parts[:-1]:
                node = node.get(part, {})
            if parts[-1] in node and node[parts[-1]] is None:
                value: Any = model
                for part in parts:
                    value = getattr(value, part)
                if isinstance(value, str):
                    node[parts[-1]] = value
        return model


def _file_layer(doc: YamlDocument) -> dict[str, Any]:
    if doc.data is None:
        return {}
    _check_sections(doc.data, doc)
    values = _leaves(doc.data)
    version = values.get("version", CONFIG_VERSION)
    if isinstance(version, (int, float)) and not isinstance(version, bool) and version > CONFIG_VERSION:
        raise ConfigError(
            f"{doc.where(('version',))}: version = {version}: written for a newer vibsynth "
            f"(this one reads version {CONFIG_VERSION})"
        )
    return values


def _override_layer(overrides: Mapping[str, Any]) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for key, value in overrides.items():
        if isinstance(value, Mapping) and not _is_leaf(key):
            values.update(_leaves(dict(value), f"{key}."))
        else:
            values[key] = value
    return values


def load_config(
    path: str | os.PathLike[str] | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    env: Mapping[str, str] | None = None,
    user_file: bool = True,
) -> Config:
    """Load the effective configuration (defaults < user file < environment < overrides).

    Parameters
    ----------
    path : path-like, optional
        User config file (``--config``). Default: ``$VIBSYNTH_CONFIG``, else the
        platform file (:func:`user_config_file`) if it exists.
    overrides : mapping, optional
        Command-line values: nested (``{"audio": {"rate": 44100}}``) or dotted
        (``{"audio.rate": 44100}``).
    env : mapping, optional
        Environment (default ``os.environ``); see :data:`ENV_VARS`.
    user_file : bool
        Read the platform user config file when no path is given (False: defaults only).

    Returns
    -------
    config : Config

    Raises
    ------
    ConfigError
        Unreadable file, YAML syntax error, unknown key, wrong type, out-of-range value
        or inconsistent values; the message names file, line, key, value and the allowed
        range (:class:`~vibsynth.settings.validation.InvalidConfigError`: with ``.problems``).
    """
    env = os.environ if env is None else env
    layers = _Layers()
    default_doc = parse_yaml(default_config_text(), DEFAULT_CONFIG_NAME)
    layers.add(_file_layer(default_doc), default_doc, lambda k: f"default ({default_doc.where(tuple(k.split('.')))})")
    files = [DEFAULT_CONFIG_NAME]

    user_path: Path | None = None
    if path is not None:
        user_path = Path(path).expanduser()
    elif env.get(CONFIG_ENV_VAR):
        user_path = Path(env[CONFIG_ENV_VAR]).expanduser()
    elif user_file and user_config_file().is_file():
        user_path = user_config_file()
    if user_path is not None:
        doc = read_yaml_file(user_path)
        layers.add(_file_layer(doc), doc, lambda k: doc.where(tuple(k.split("."))))
        files.append(str(user_path))

    env_values: dict[str, Any] = {}
    env_names: dict[str, str] = {}
    for var, dotted in ENV_VARS.items():
        if var in env and env[var] != "":
            env_values[dotted] = _parse_env_value(var, env[var])
            env_names[dotted] = var
    if env_values:
        where = {k: f"environment variable {v}" for k, v in env_names.items()}
        layers.add(env_values, _KeyLocator(where, "environment"), lambda k: f"env {env_names[k]}")

    if overrides:
        layers.add(_override_layer(overrides), FixedLocator("command line"), lambda k: "command line")

    model = layers.finish()
    return Config(data=layers.data, sources=layers.sources, files=files, model=model)


def check_config_file(path: str | os.PathLike[str]) -> Config:
    """Validate one config file on top of the defaults (no user file, no environment)."""
    return load_config(path, env={}, user_file=False)


def parse_override(text: str) -> tuple[str, Any]:
    """Parse a command-line ``KEY=VALUE`` (value in YAML syntax, e.g. ``audio.rate=44100``)."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"command line: --set {text!r}: expected KEY=VALUE, e.g. --set audio.rate=44100")
    value = yaml_value(raw, f"command line: --set {key.strip()}") if raw.strip() else None
    return key.strip(), value


def add_config_arguments(parser: Any) -> None:
    """Add ``--config FILE`` and ``--set KEY=VALUE`` (repeatable) to an argparse parser."""
    parser.add_argument(
        "--config",
        metavar="FILE.yaml",
        type=Path,
        help=f"user config file (default: ${CONFIG_ENV_VAR}, else {user_config_file()})",
    )
    parser.add_argument(
        "--set",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        dest="config_set",
        help="override one config value (YAML syntax), e.g. --set audio.rate=44100; repeatable",
    )


def config_from_args(args: Any, *, extra: Mapping[str, Any] | None = None) -> Config:
    """The effective config for parsed arguments (see :func:`add_config_arguments`).

    ``extra``: further command-line values (dotted keys) from a command's own flags,
    applied after ``--set``; ``None`` values are left out.
    """
    overrides: dict[str, Any] = dict(parse_override(text) for text in getattr(args, "config_set", None) or [])
    for key, value in (extra or {}).items():
        if value is not None:
            overrides[key] = value
    return load_config(getattr(args, "config", None), overrides=overrides or None)


def settings_from_args(args: Any, *, extra: Mapping[str, Any] | None = None) -> VibsynthConfig:
    """The typed settings for parsed arguments, validated once (see :func:`config_from_args`).

    The edge of a command: what it hands on is this model (or sections of it), never the dict.
    """
    return config_from_args(args, extra=extra).settings


def default_settings() -> VibsynthConfig:
    """The typed settings of the packaged defaults and the environment (no user config file)."""
    return load_config(user_file=False).settings
