"""Actuator layouts: where each output channel's actuator sits, shipped as named files a config can name.

A position may name the actuator profile of its channel (``profile: vest-ch3``): that channel
is then equalised for its own actuator by a per-channel trim (``actuator.channel_profiles``
wins over it; :func:`channel_profile_names`).

``layout: glove`` in the config names a layout file (shipped in ``vibsynth/data/layouts/`` or the
user's ``layouts/`` folder beside the config file, which wins); ``layout: {1: {x: .., y: ..}}``
gives the positions inline. A layout file is checked against :class:`LayoutFileModel`; errors
name ``file:line``, the key and the range, like the config's.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Annotated

from pydantic import BeforeValidator, ConfigDict
from pydantic_core import PydanticCustomError

from vibsynth.errors import ConfigError
from vibsynth.settings.actuators import (
    actuator_profiles,
    load_actuator_profile,
    named_files,
    profile_rate_problem,
    user_profile_dir,
)
from vibsynth.settings.fields import SettingsModel, cross_problem, setting
from vibsynth.settings.models_config import (
    CHANNEL_PROFILE_FIELD,
    PROFILE_NAME,
    ChannelPosition,
    VibsynthConfig,
    check_layout,
)
from vibsynth.settings.paths import user_config_file
from vibsynth.settings.validation import did_you_mean, model_spec, validate
from vibsynth.settings.yamldoc import read_yaml_file

__all__ = [
    "LAYOUT_RESOURCE",
    "LayoutFileModel",
    "Layout",
    "user_layout_dir",
    "layout_files",
    "read_layout_file",
    "load_layout",
    "resolve_layout",
    "layout_problem",
    "channel_profile_names",
    "channel_profiles_problem",
]

LAYOUT_RESOURCE = "layouts"


class LayoutFileModel(SettingsModel):
    """A layout file: a named set of actuator positions (``channels``) a config can name."""

    model_config = ConfigDict(title="vibsynth layout")

    name: str | None = setting(
        None,
        "the file name without .yaml (optional; if given it must match)",
        allowed="a layout name (letters, digits, . _ -)",
        pattern=PROFILE_NAME,
    )
    description: str = setting("", "what the layout is and how its axes point", allowed="text (a string)")
    channels: Annotated[dict[int, ChannelPosition], BeforeValidator(check_layout)] = setting(
        ...,
        "output channel (1-based) -> {x, y, z, name} in metres, and optionally its actuator profile",
        allowed="a mapping {output channel 1..64: {x: m, y: m, z: m (default 0), name: text, profile: name}}",
        schema={"propertyNames": {"pattern": "^[1-9][0-9]*$"}},
        min_length=1,
    )


class Layout:
    """A resolved layout: which channels are placed, where, and their names.

    Parameters
    ----------
    positions : mapping of int to ChannelPosition
        1-based output channel -> position.
    name : str or None
        The layout file's name (None for an inline layout).

    Attributes
    ----------
    channels : tuple of int
        The placed channels, 0-based, ascending.
    coordinates : list of (x, y, z)
        Their positions in metres, in the order of ``channels``.
    names : list of str or None
    profiles : list of str or None
        Each placed channel's own actuator profile (None: ``actuator.profile``).
    """

    def __init__(self, positions: Mapping[int, ChannelPosition], name: str | None = None) -> None:
        self.name = name
        ordered = sorted(positions.items())
        self.channels = tuple(channel - 1 for channel, _ in ordered)
        self.coordinates = [(p.x, p.y, p.z) for _, p in ordered]
        self.names = [p.name for _, p in ordered]
        self.profiles = [p.profile for _, p in ordered]

    def describe(self) -> str:
        """``layout glove (6 actuators)`` or ``inline layout (4 actuators)``."""
        what = f"layout {self.name}" if self.name else "inline layout"
        return f"{what} ({len(self.channels)} actuator{'s' if len(self.channels) != 1 else ''})"


def user_layout_dir() -> Path:
    """Folder for user layouts: ``layouts/`` in the platform config folder."""
    return user_config_file().parent / "layouts"


def layout_files() -> dict[str, str]:
    """Available layouts: name -> file (user layouts override shipped ones)."""
    return named_files(resources.files("vibsynth.data").joinpath(LAYOUT_RESOURCE), user_layout_dir())


def read_layout_file(path: str | Path, name: str | None = None) -> LayoutFileModel:
    """Read and validate one layout file (``name``: the expected name, default the file stem).

    Raises
    ------
    ConfigError
        ``glove.yaml:7: channels.3.x = 12: outside the allowed range [-10, 10] m``.
    """
    p = Path(path)
    name = p.stem if name is None else name
    doc = read_yaml_file(p, what="a layout")
    if not isinstance(doc.data, dict):
        raise ConfigError(f"{doc.origin}: a layout must be a mapping with name, description, channels")
    model: LayoutFileModel = validate(model_spec(LayoutFileModel), doc.data, doc, ConfigError)
    if model.name is not None and model.name != name:
        raise ConfigError(f"{doc.where(('name',))}: name = {model.name!r} does not match the file name {name}.yaml")
    return model


def load_layout(name: str) -> LayoutFileModel:
    """Read and validate a layout by name.

    Raises
    ------
    ConfigError
        No such layout (the message lists those available), or a broken file.
    """
    files = layout_files()
    if name not in files:
        raise ConfigError(
            f"unknown layout {name!r}{did_you_mean(name, list(files))} (available: {', '.join(sorted(files))}; "
            f"user layouts go in {user_layout_dir()})"
        )
    return read_layout_file(files[name], name)


def resolve_layout(value: str | Mapping[int, ChannelPosition] | None) -> Layout | None:
    """The typed ``layout`` setting with every position (a named layout's file is read), or None without one.

    ``value``: ``settings.layout``, a layout name or the inline positions.
    """
    if value is None:
        return None
    if isinstance(value, str):
        return Layout(load_layout(value).channels, value)
    return Layout(value)


def layout_problem(config: VibsynthConfig) -> PydanticCustomError | None:
    """The rule between a named layout's file and ``audio.channels`` broken by ``config``, if any.

    One of the loader's file checks (:data:`~vibsynth.settings.models_config.FILE_CHECKS`); an
    inline layout is checked by the model itself. A broken layout file raises its own
    :class:`ConfigError` naming the file and line.
    """
    value = config.layout
    if not isinstance(value, str):
        return channel_profiles_problem(config)
    channels = config.audio.channels
    files = layout_files()
    if value not in files:
        return cross_problem(
            f"layout = {value!r}: no such layout{did_you_mean(value, list(files))} (allowed: "
            f"{', '.join(sorted(files)) or 'none found'}, a mapping of positions, or null; user layouts go "
            f"in {user_layout_dir()})",
            "layout",
        )
    top = max(read_layout_file(files[value], value).channels)
    if top > channels:
        return cross_problem(
            f"layout {value} places channel {top} but audio.channels = {channels} (allowed: channels 1..{channels})",
            "layout",
            "audio.channels",
        )
    return channel_profiles_problem(config)


def channel_profiles_problem(config: VibsynthConfig) -> PydanticCustomError | None:
    """What is wrong with the channels' own actuator profiles, or None.

    One of the loader's file checks (:func:`layout_problem` runs it): ``actuator.channel_profiles``
    longer than ``audio.channels``; a channel naming no profile file; a profile measured at
    another rate; measured (absolute) and relative profiles mixed among the channels (their
    responses cannot be compared).
    """
    pattern = config.actuator.channel_profiles
    channels = config.audio.channels
    if isinstance(pattern, list) and len(pattern) > channels:
        return cross_problem(
            f"actuator.channel_profiles lists {len(pattern)} channels but audio.channels = {channels} "
            f"(allowed: up to {channels} entries)",
            "actuator.channel_profiles",
            "audio.channels",
        )
    try:
        names = channel_profile_names(config)
    except ConfigError:
        return None  # a broken layout file says so, with its line, where it is read
    if not any(names):
        return None
    key = "actuator.channel_profiles" if pattern is not None else "layout"
    where = key
    if pattern is None and isinstance(config.layout, str):
        where = f"layout {config.layout} ({layout_files().get(config.layout, '?')})"
    available = actuator_profiles()
    kinds: dict[bool, list[str]] = {}
    for channel, name in enumerate(names, start=1):
        if name is None:
            if config.actuator.response is not None:
                kinds.setdefault(False, []).append(f"{channel} (actuator.response)")
                continue
            name = config.actuator.profile
            if name is None or name not in available:
                kinds.setdefault(False, []).append(f"{channel} ({name or 'flat'})")
                continue
        elif name not in available:
            return cross_problem(
                f"{where}: channel {channel}'s profile {name!r} does not exist (allowed: "
                f"{', '.join(sorted(available)) or 'none found'}; user profiles go in {user_profile_dir()}; "
                f"calibrate response --channels all -o NAME writes NAME-ch1, NAME-ch2, ...)",
                key,
            )
        try:
            profile = load_actuator_profile(name)
        except ConfigError:
            return None  # a broken profile file says so, with its line, where it is read
        rate = profile_rate_problem(profile, config.audio.rate)
        if rate is not None:
            return cross_problem(f"{where}: channel {channel}: {rate}", key, "audio.rate")
        kinds.setdefault(bool(profile["absolute"]), []).append(f"{channel} ({name})")
    if len(kinds) > 1:
        return cross_problem(
            f"{where}: channels {', '.join(kinds[True])} have measured (absolute) profiles but channels "
            f"{', '.join(kinds[False])} relative ones: their responses cannot be compared (allowed: every channel "
            "measured with one sensor chain, calibrate response --channels all, or every channel relative)",
            key,
            "actuator.profile",
        )
    return None


def channel_profile_names(settings: VibsynthConfig) -> list[str | None]:
    """Each output channel's own actuator profile name (0-based list, ``audio.channels`` long).

    ``actuator.channel_profiles`` wins (a pattern: ``vest-ch{n}`` -> ``vest-ch1``, ...; a list:
    channel 1 first, shorter lists leave the rest None); else the layout's per-position
    ``profile``; None = the channel uses ``actuator.profile`` (no trim). ``settings``: the typed
    model (it reads ``audio.channels``, ``actuator.channel_profiles`` and ``layout``).
    """
    channels = settings.audio.channels
    value = settings.actuator.channel_profiles
    if isinstance(value, str):
        return [value.replace(CHANNEL_PROFILE_FIELD, str(n)) for n in range(1, channels + 1)]
    if isinstance(value, list):
        return [value[c] if c < len(value) else None for c in range(channels)]
    names: list[str | None] = [None] * channels
    layout = resolve_layout(settings.layout)
    if layout is not None:
        for channel, profile in zip(layout.channels, layout.profiles, strict=True):
            if channel < channels:
                names[channel] = profile
    return names
