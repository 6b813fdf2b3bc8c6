"""Configuration: a validated, layered YAML tree with the origin of every value.

Layers, lowest first (a later layer overrides single keys of an earlier one):

1. built-in defaults: the package file ``vibsynth/data/config/default.yaml``
   (``config/default.yaml`` at the repository root is a symlink to it: one source);
2. the user config file: ``path`` (``--config``), else ``$VIBSYNTH_CONFIG``, else
   ``config.yaml`` in the platform config folder (see :func:`user_config_file`), if it exists;
3. environment variables for per-run settings (:data:`ENV_VARS`);
4. command-line overrides (``overrides``: nested or dotted keys).

Every leaf key is validated (type, range, allowed values; unknown keys are errors).
Errors raise :class:`~vibsynth.errors.ConfigError` with a message naming the file,
the line, the key, the value and what is allowed, e.g.::

    my.yaml:7: audio.rate = 100: outside the allowed range [2400, 384000] (Hz)

API contract used by the rest of the package:

* ``load_config(path=None, *, overrides=None) -> Config``
* ``Config.data``: nested dict with every key of ``vibsynth/data/config/default.yaml``
* ``Config.section(name) -> dict``; ``Config.get("audio.rate")``
* ``Config.sources``: dotted key -> where its value came from
* ``resolve_actuator_response(config) -> list[(hz, db)]``
"""

from __future__ import annotations

import copy
import math
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from vibsynth.errors import ConfigError
from vibsynth.settings.yamldoc import Path_, YamlDocument, parse_yaml, read_yaml_file, short_repr, yaml_value

DEFAULT_CONFIG_RESOURCE = "config/default.yaml"
CONFIG_VERSION = 1
APP_NAME = "vibsynth"

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
#: Environment variable naming the user config file (``--config`` wins over it).
CONFIG_ENV_VAR = "VIBSYNTH_CONFIG"


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _fmt(value: Any) -> str:
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return repr(value)
    if value is None or _is_number(value):
        return str(value)
    return short_repr(value)


@dataclass(frozen=True)
class Spec:
    """How one leaf value is checked.

    ``check(value)`` returns ``None`` when valid, else a short reason; ``allowed``
    describes the legal values for messages and docs.
    """

    allowed: str
    check: Callable[[Any], str | None]
    doc: str = ""


def number(
    low: float | None = None,
    high: float | None = None,
    *,
    integer: bool = False,
    nullable: bool = False,
    low_open: bool = False,
    unit: str = "",
    doc: str = "",
) -> Spec:
    """A number (int or float; bool refused) within [low, high] (``low_open``: (low, high])."""
    kind = "an integer" if integer else "a number"
    lo = "(" if low_open else "["
    rng = f"{lo}{'-inf' if low is None else f'{low:g}'}, {'inf' if high is None else f'{high:g}'}]"
    allowed = f"{kind} in {rng}" + (f" {unit}" if unit else "") + (" or null" if nullable else "")

    def check(value: Any) -> str | None:
        if value is None:
            return None if nullable else "must not be null"
        if not _is_number(value):
            return f"must be {kind}"
        if not math.isfinite(float(value)):
            return "must be finite"
        if integer and not float(value).is_integer():
            return f"must be {kind}"
        v = float(value)
        if (low is not None and (v < low or (low_open and v == low))) or (high is not None and v > high):
            return f"outside the allowed range {rng}" + (f" {unit}" if unit else "")
        return None

    return Spec(allowed, check, doc)


def boolean(doc: str = "") -> Spec:
    return Spec("true or false", lambda v: None if isinstance(v, bool) else "must be true or false", doc)


def choice(*values: Any, nullable: bool = False, doc: str = "") -> Spec:
    allowed = "one of " + ", ".join(str(v) for v in values) + (" or null" if nullable else "")

    def check(value: Any) -> str | None:
        if value is None and nullable:
            return None
        return None if value in values and not isinstance(value, bool) else "not an allowed value"

    return Spec(allowed, check, doc)


def string(*, nullable: bool = False, pattern: str | None = None, what: str = "a string", doc: str = "") -> Spec:
    allowed = what + (" or null" if nullable else "")

    def check(value: Any) -> str | None:
        if value is None:
            return None if nullable else "must not be null"
        if not isinstance(value, str):
            return f"must be {what}"
        if pattern is not None and not re.fullmatch(pattern, value):
            return f"must be {what}"
        return None

    return Spec(allowed, check, doc)


def any_of(*specs: Spec, doc: str = "") -> Spec:
    allowed = " or ".join(s.allowed for s in specs)

    def check(value: Any) -> str | None:
        reasons = [s.check(value) for s in specs]
        if any(r is None for r in reasons):
            return None
        return next((r for r in reasons if r and "outside" in r), "not an allowed value")

    return Spec(allowed, check, doc)


def _points(
    x_name: str, x_low: float, x_low_open: bool, y_low: float, y_high: float, min_points: int, nullable: bool, doc: str
) -> Spec:
    lo = "(" if x_low_open else "["
    allowed = (
        f"a list of at least {min_points} pairs [{x_name}, value] with {x_name} in {lo}{x_low:g}, inf) "
        f"strictly increasing and value in [{y_low:g}, {y_high:g}]" + (", or null" if nullable else "")
    )

    def check(value: Any) -> str | None:
        if value is None:
            return None if nullable else "must not be null"
        if not isinstance(value, list):
            return "must be a list of pairs"
        if len(value) < min_points:
            return f"needs at least {min_points} points"
        previous = None
        for i, point in enumerate(value):
            if not (isinstance(point, list) and len(point) == 2 and all(_is_number(v) for v in point)):
                return f"item {i} ({point!r}) is not a pair of numbers"
            x, y = float(point[0]), float(point[1])
            if not (math.isfinite(x) and math.isfinite(y)):
                return f"item {i} ({point!r}) is not finite"
            if x < x_low or (x_low_open and x == x_low):
                return f"item {i}: {x_name} {x:g} is outside {lo}{x_low:g}, inf)"
            if not y_low <= y <= y_high:
                return f"item {i}: value {y:g} is outside [{y_low:g}, {y_high:g}]"
            if previous is not None and x <= previous:
                return f"item {i}: {x_name} {x:g} does not increase (previous {previous:g})"
            previous = x
        return None

    return Spec(allowed, check, doc)


def _channel_list(value: Any) -> str | None:
    if value is None:
        return None
    if not isinstance(value, list) or not value:
        return "must be a non-empty list of device outputs (1-based integers)"
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value):
        return "every entry must be an integer >= 1 (device outputs are 1-based)"
    if len(set(value)) != len(value):
        return "lists a device output twice"
    return None


def _addresses(value: Any) -> str | None:
    """``osc.allow``: checked by the OSC server's own parser, so what passes here starts the server."""
    from vibsynth.settings.allow_list import parse_allow_list

    try:
        parse_allow_list(value)
    except ConfigError as exc:
        return str(exc)
    return None


def _midi_channel_map(value: Any) -> str | None:
    if not isinstance(value, dict) or not value:
        return "must be a mapping {MIDI channel 1-16: 'all' or [actuator channels]}"
    for key, target in value.items():
        if not (isinstance(key, int) and not isinstance(key, bool) and 1 <= key <= 16):
            return f"key {key!r} is not a MIDI channel 1..16"
        if target == "all":
            continue
        if not (
            isinstance(target, list)
            and target
            and all(isinstance(t, int) and not isinstance(t, bool) and t >= 1 for t in target)
        ):
            return f"channel {key}: {target!r} must be 'all' or a list of actuator channels (1-based)"
    return None


_BINDING_KEYS = {"cc": (0, 127), "channel": (1, 16)}


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _nrpn_problem(value: Any) -> str | None:
    """An NRPN number: 0..16383, or [msb, lsb] with each 0..127."""
    if _is_int(value) and 0 <= value <= 16383:
        return None
    if isinstance(value, list) and len(value) == 2 and all(_is_int(v) and 0 <= v <= 127 for v in value):
        return None
    return f"nrpn {value!r} must be 0..16383 or [msb, lsb] with each 0..127"


def _midi_bindings(value: Any) -> str | None:
    if not isinstance(value, list):
        return "must be a list of bindings like {cc: 74} or {nrpn: [1, 0]}"
    for i, item in enumerate(value):
        if not isinstance(item, dict) or ("cc" in item) == ("nrpn" in item):
            return f"item {i} ({item!r}) must be a mapping with either a cc or an nrpn number, e.g. {{cc: 74}}"
        for key, val in item.items():
            if key == "invert":
                if not isinstance(val, bool):
                    return f"item {i}: invert must be true or false"
                continue
            if key == "nrpn":
                problem = _nrpn_problem(val)
                if problem:
                    return f"item {i}: {problem}"
                continue
            if key == "range":
                if not (
                    isinstance(val, list)
                    and len(val) == 2
                    and all(_is_number(v) and math.isfinite(v) for v in val)
                    and val[0] < val[1]
                ):
                    return f"item {i}: range {val!r} must be [low, high] with finite low < high"
                continue
            if key not in _BINDING_KEYS:
                return f"item {i}: unknown key {key!r} (allowed: cc, nrpn, channel, invert, range)"
            lo, hi = _BINDING_KEYS[key]
            if not (_is_int(val) and lo <= val <= hi):
                return f"item {i}: {key} {val!r} is outside [{lo}, {hi}]"
    return None


def _midi_nrpn(value: Any) -> str | None:
    if not isinstance(value, dict):
        return "must be a mapping {intensity: [msb, lsb], balance: [msb, lsb]}"
    for knob, number_ in value.items():
        if knob not in ("intensity", "balance"):
            return f"unknown knob {knob!r} (allowed: intensity, balance)"
        problem = _nrpn_problem(number_)
        if problem:
            return f"{knob}: {problem}"
    return None


def custom(allowed: str, fn: Callable[[Any], str | None], doc: str = "") -> Spec:
    return Spec(allowed, fn, doc)


_PROFILE_NAME = r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}"

#: Every leaf key of the configuration and how it is validated (docs/config.md lists them).
SCHEMA: dict[str, Spec] = {
    "version": number(1, 1, integer=True, doc="config schema version"),
    # audio
    "audio.backend": choice("auto", "sounddevice", "null", "wav"),
    "audio.device": any_of(
        string(nullable=True, what="a device name substring"), number(0, None, integer=True, doc="device index")
    ),
    "audio.host_api": string(nullable=True, what="a host API name"),
    "audio.rate": number(2400, 384000, integer=True, unit="Hz"),
    "audio.block_size": number(16, 8192, integer=True, unit="frames"),
    "audio.latency": any_of(choice("low", "high"), number(0, 2, low_open=True, unit="s")),
    "audio.channels": number(1, 64, integer=True),
    "audio.channel_map": custom("null or a list of distinct device outputs (1-based), one per channel", _channel_list),
    # bank
    "bank.balance_min": number(-10, 0, unit="(knob units)"),
    "bank.balance_max": number(0, 10, unit="(knob units)"),
    "bank.levels": number(2, 1001, integer=True),
    "bank.loop_seconds": number(0.5, 60, unit="s"),
    "bank.cache_dir": string(nullable=True, what='a folder path ("" disables the cache)'),
    "bank.seed": number(0, 2**32 - 1, integer=True),
    # knobs
    "knobs.ceiling_db": number(-120, 0, unit="dB"),
    "knobs.range_db": number(0, 120, low_open=True, unit="dB"),
    "knobs.glide_ms": number(0, 10000, unit="ms"),
    "knobs.mute_fade_ms": number(0, 1000, unit="ms"),
    "knobs.limiter_ceiling": number(0, 1, low_open=True, unit="(full scale)"),
    "knobs.balance_min": number(-10, 0, unit="(knob units)"),
    "knobs.balance_max": number(0, 10, unit="(knob units)"),
    "knobs.initial_intensity": number(0, 1),
    "knobs.initial_balance": number(-10, 10, unit="(knob units)"),
    "knobs.schedule_capacity": number(
        1, 1_000_000, integer=True, doc="most timetagged commands waiting at once; more are refused"
    ),
    # actuator
    "actuator.profile": string(nullable=True, pattern=_PROFILE_NAME, what="a profile name"),
    "actuator.response": _points("Hz", 0, True, -60, 60, 1, True, "explicit response points"),
    "actuator.max_boost_db": number(0, 40, unit="dB"),
    # osc
    "osc.enabled": boolean(),
    "osc.host": string(pattern=r"\S+", what="a host name or IP address"),
    "osc.port": number(0, 65535, integer=True, doc="0 = any free port"),
    "osc.prefix": string(pattern=r"(/[A-Za-z0-9_.\-]+)+", what="an OSC address like /vibsynth (no trailing /)"),
    "osc.allow": custom(
        "a list of IP addresses, networks or 'localhost', e.g. ['127.0.0.1', '192.168.1.0/24']", _addresses
    ),
    "osc.reply_port": number(1, 65535, integer=True, nullable=True),
    "osc.schedule_horizon_s": number(0, 3600, low_open=True, unit="s"),
    "osc.notify_rate_hz": number(0, 1000, low_open=True, unit="Hz"),
    "osc.tcp": boolean(),
    "osc.tcp_max_connections": number(1, 1024, integer=True),
    "osc.tcp_max_per_peer": number(1, 1024, integer=True),
    "osc.tcp_idle_timeout_s": number(0, 86400, low_open=True, unit="s"),
    # midi
    "midi.enabled": boolean(),
    "midi.port": any_of(string(nullable=True, what="a port name substring"), number(0, None, integer=True)),
    "midi.virtual": boolean(),
    "midi.mode": choice("gate", "continuous"),
    "midi.release_ms": number(0, 10000, unit="ms"),
    "midi.velocity_curve": number(0.1, 10),
    "midi.pitch_bend_range": number(0, 8, unit="(knob units)"),
    "midi.channel_map": custom(
        "a mapping {MIDI channel 1-16: 'all' or [actuator channels, 1-based]}", _midi_channel_map
    ),
    "midi.mpe": boolean(),
    "midi.attack_ms": number(0, 10000, nullable=True, unit="ms"),
    "midi.cc_glide_max_ms": number(0, 10000, unit="ms"),
    "midi.reconnect_interval_s": number(0.05, 60, unit="s"),
    "midi.nrpn": custom("a mapping {intensity: [msb, lsb], balance: [msb, lsb]} (or 0..16383)", _midi_nrpn),
    "midi.mapping.intensity": custom(
        "a list of bindings like {cc: 11} or {nrpn: [1, 0]} (optional channel 1-16, invert, range [low, high])",
        _midi_bindings,
    ),
    "midi.mapping.balance": custom(
        "a list of bindings like {cc: 74} or {nrpn: [1, 1]} (optional channel 1-16, invert, range [low, high])",
        _midi_bindings,
    ),
    # speed
    "speed.curve": _points("mm/s", 0, False, 0, 1, 2, False, "speed -> intensity"),
    "speed.balance_per_decade": number(-4, 4, unit="(knob units per decade)"),
    # presets
    "presets.user_dir": string(nullable=True, what="a folder path"),
    "presets.watch": boolean(),
}

_SECTIONS = {k.rsplit(".", 1)[0] for k in SCHEMA if "." in k}
_SECTIONS |= {".".join(k.split(".")[:i]) for k in SCHEMA for i in range(1, k.count(".") + 1)}


def default_config_text() -> str:
    """Text of the built-in default config (package data)."""
    return resources.files("vibsynth.data").joinpath(DEFAULT_CONFIG_RESOURCE).read_text(encoding="utf-8")


def default_config_data() -> dict[str, Any]:
    """The built-in defaults as a nested dict."""
    return parse_yaml(default_config_text(), "vibsynth/data/" + DEFAULT_CONFIG_RESOURCE).data


def _leaves(data: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Dotted leaf keys of a nested dict, as defined by :data:`SCHEMA` (unknown nested dicts are walked)."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if dotted not in SCHEMA and isinstance(value, dict):
            out.update(_leaves(value, dotted + "."))
        else:
            out[dotted] = value
    return out


def _set(data: dict[str, Any], dotted: str, value: Any) -> None:
    node = data
    parts = dotted.split(".")
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = copy.deepcopy(value)


def _close(key: str, candidates: list[str]) -> str:
    import difflib

    near = difflib.get_close_matches(key, candidates, n=3, cutoff=0.6)
    return f"; did you mean {', '.join(near)}?" if near else ""


#: Keys where YAML ``null`` (unquoted) means the string "null" (e.g. the null audio backend).
_NULL_MEANS_STRING = {"audio.backend"}


def _validate_layer(values: dict[str, Any], where: Callable[[str], str], *, what: str = "key") -> None:
    """Check each dotted leaf of one layer; ``where(dotted)`` gives ``file:line`` for messages."""
    for dotted, value in list(values.items()):
        if dotted in _NULL_MEANS_STRING and value is None:
            values[dotted] = value = "null"  # type: ignore[index]
        spec = SCHEMA.get(dotted)
        if spec is None:
            if dotted in _SECTIONS:
                raise ConfigError(f"{where(dotted)}: {dotted} must be a section (a mapping of keys), got {_fmt(value)}")
            parent = dotted.rsplit(".", 1)[0] if "." in dotted else ""
            known = (
                sorted(k.rsplit(".", 1)[-1] for k in SCHEMA if k.startswith(parent + "."))
                if parent
                else sorted({k.split(".")[0] for k in SCHEMA})
            )
            raise ConfigError(
                f"{where(dotted)}: unknown {what} {dotted!r}{_close(dotted, list(SCHEMA))} "
                f"(allowed {'in ' + parent if parent else 'sections'}: {', '.join(known)})"
            )
        reason = spec.check(value)
        if reason is not None:
            raise ConfigError(f"{where(dotted)}: {dotted} = {_fmt(value)}: {reason} (allowed: {spec.allowed})")


def _check_sections(data: Any, doc: YamlDocument, prefix: Path_ = ()) -> None:
    """Top level and sections must be mappings."""
    if not isinstance(data, dict):
        name = ".".join(prefix) or "the file"
        raise ConfigError(f"{doc.where(prefix)}: {name} must be a mapping of keys, got {_fmt(data)}")
    for key, value in data.items():
        dotted = ".".join(prefix + (str(key),))
        if dotted in _SECTIONS and dotted not in SCHEMA:
            if value is None:
                data[key] = {}
                continue
            _check_sections(value, doc, prefix + (str(key),))


def _cross_check(data: Mapping[str, Any], sources: Mapping[str, str]) -> None:
    def fail(key: str | tuple[str, ...], message: str) -> None:
        keys = (key,) if isinstance(key, str) else key
        # blame the value a person set (file, env, command line) rather than a default
        chosen = next((k for k in keys if not sources.get(k, "default").startswith("default")), keys[0])
        raise ConfigError(f"{sources.get(chosen, 'config')}: {message}")

    audio, bank, knobs = data["audio"], data["bank"], data["knobs"]
    if audio["channel_map"] is not None and len(audio["channel_map"]) != audio["channels"]:
        fail(
            ("audio.channel_map", "audio.channels"),
            f"audio.channel_map = {audio['channel_map']}: has {len(audio['channel_map'])} "
            f"entries but audio.channels = {audio['channels']} (allowed: one device output per channel)",
        )
    if bank["balance_min"] >= bank["balance_max"]:
        fail(
            ("bank.balance_max", "bank.balance_min"),
            f"bank.balance_max = {bank['balance_max']} must be above bank.balance_min = {bank['balance_min']}",
        )
    if knobs["balance_min"] >= knobs["balance_max"]:
        fail(
            ("knobs.balance_max", "knobs.balance_min"),
            f"knobs.balance_max = {knobs['balance_max']} must be above knobs.balance_min = {knobs['balance_min']}",
        )
    if knobs["balance_min"] < bank["balance_min"] or knobs["balance_max"] > bank["balance_max"]:
        fail(
            ("knobs.balance_min", "knobs.balance_max", "bank.balance_min", "bank.balance_max"),
            f"live balance range [{knobs['balance_min']:g}, {knobs['balance_max']:g}] (knobs) must lie "
            f"within the bank's grid [{bank['balance_min']:g}, {bank['balance_max']:g}] (bank.balance_min/max)",
        )
    if not knobs["balance_min"] <= knobs["initial_balance"] <= knobs["balance_max"]:
        fail(
            ("knobs.initial_balance", "knobs.balance_min", "knobs.balance_max"),
            f"knobs.initial_balance = {knobs['initial_balance']}: outside the live range "
            f"[{knobs['balance_min']:g}, {knobs['balance_max']:g}] (knobs.balance_min/max)",
        )
    channels = audio["channels"]
    for midi_channel, target in data["midi"]["channel_map"].items():
        if isinstance(target, list) and max(target) > channels:
            fail(
                ("midi.channel_map", "audio.channels"),
                f"midi.channel_map = {data['midi']['channel_map']}: MIDI channel {midi_channel} "
                f"targets actuator channel {max(target)} but audio.channels = {channels} (allowed: 1..{channels})",
            )
    profile = data["actuator"]["profile"]
    if profile is not None and data["actuator"]["response"] is None:
        from vibsynth.settings.actuators import actuator_profiles, user_profile_dir  # actuators imports this module

        names = actuator_profiles()
        if profile not in names:
            fail(
                "actuator.profile",
                f"actuator.profile = {profile!r}: no such profile (allowed: "
                f"{', '.join(sorted(names)) or 'none found'}, or null; user profiles go in {user_profile_dir()})",
            )


@dataclass
class Config:
    """The effective configuration.

    Attributes
    ----------
    data : dict
        Nested dict with every key of the default config.
    sources : dict of str to str
        Dotted leaf key -> where its value came from (``file:line``, ``env VAR``, ``command line``).
    files : list of str
        Config files read, lowest layer first.
    """

    data: dict[str, Any]
    sources: dict[str, str] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)

    def section(self, name: str) -> dict[str, Any]:
        """One top-level section (e.g. ``"audio"``)."""
        try:
            return self.data[name]
        except KeyError:
            raise ConfigError(f"unknown config section {name!r}; sections: {', '.join(self.data)}") from None

    def get(self, dotted: str) -> Any:
        """A value by dotted key, e.g. ``config.get("osc.port")``."""
        node: Any = self.data
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                raise ConfigError(f"unknown config key {dotted!r}{_close(dotted, list(SCHEMA))}")
            node = node[part]
        return node

    def leaves(self) -> dict[str, Any]:
        """Every dotted leaf key and its value, in file order."""
        return _leaves(self.data)


def user_config_file() -> Path:
    """The platform user config file (``config.yaml`` in the platform config folder).

    Linux: ``~/.config/vibsynth/config.yaml`` (``$XDG_CONFIG_HOME``); macOS:
    ``~/Library/Application Support/vibsynth/config.yaml``; Windows:
    ``%LOCALAPPDATA%\\vibsynth\\config.yaml``.
    """
    import platformdirs

    return Path(platformdirs.user_config_dir(APP_NAME, appauthor=False)) / "config.yaml"


def _parse_env_value(name: str, text: str) -> Any:
    value = yaml_value(text, f"environment variable {name}")
    return text if isinstance(value, (dict, list)) else value


def _apply_layer(
    data: dict[str, Any], sources: dict[str, str], values: Mapping[str, Any], source: Callable[[str], str]
) -> None:
    for dotted, value in values.items():
        _set(data, dotted, value)
        sources[dotted] = source(dotted)


def _file_layer(doc: YamlDocument) -> dict[str, Any]:
    if doc.data is None:
        return {}
    _check_sections(doc.data, doc)
    values = _leaves(doc.data)
    version = values.get("version", CONFIG_VERSION)
    if _is_number(version) and version > CONFIG_VERSION:
        raise ConfigError(
            f"{doc.where(('version',))}: version = {version}: written for a newer vibsynth "
            f"(this one reads version {CONFIG_VERSION})"
        )
    _validate_layer(values, lambda k: doc.where(tuple(k.split("."))))
    return values


def _override_layer(overrides: Mapping[str, Any]) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for key, value in overrides.items():
        if isinstance(value, Mapping) and key not in SCHEMA:
            for sub, v in _leaves(dict(value), f"{key}.").items():
                values[sub] = v
        else:
            values[key] = value
    _validate_layer(values, lambda k: "command line")
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
        or inconsistent values; the message names file, line, key, value and the allowed range.
    """
    env = os.environ if env is None else env
    default_name = "vibsynth/data/" + DEFAULT_CONFIG_RESOURCE
    default_doc = parse_yaml(default_config_text(), default_name)
    data: dict[str, Any] = {}
    sources: dict[str, str] = {}
    _apply_layer(
        data, sources, _file_layer(default_doc), lambda k: f"default ({default_doc.where(tuple(k.split('.')))})"
    )
    files = [default_name]

    user_path: Path | None = None
    if path is not None:
        user_path = Path(path).expanduser()
    elif env.get(CONFIG_ENV_VAR):
        user_path = Path(env[CONFIG_ENV_VAR]).expanduser()
    elif user_file and user_config_file().is_file():
        user_path = user_config_file()
    if user_path is not None:
        doc = read_yaml_file(user_path)
        _apply_layer(data, sources, _file_layer(doc), lambda k, d=doc: d.where(tuple(k.split("."))))
        files.append(str(user_path))

    env_values: dict[str, Any] = {}
    env_names: dict[str, str] = {}
    for var, dotted in ENV_VARS.items():
        if var in env and env[var] != "":
            env_values[dotted] = _parse_env_value(var, env[var])
            env_names[dotted] = var
    if dotted_values := env_values:
        _validate_layer(dotted_values, lambda k: f"environment variable {env_names[k]}")
        _apply_layer(data, sources, dotted_values, lambda k: f"env {env_names[k]}")

    if overrides:
        _apply_layer(data, sources, _override_layer(overrides), lambda k: "command line")

    _cross_check(data, sources)
    return Config(data=data, sources=sources, files=files)


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
