"""Actuator layouts: where each output channel's actuator sits, shipped as named files a config can name.

``layout: glove`` in the config names a layout file (shipped in ``vibsynth/data/layouts/`` or the
user's ``layouts/`` folder beside the config file, which wins); ``layout: {1: {x: .., y: ..}}``
gives the positions inline. A layout file is checked against :class:`LayoutFileModel`; errors
name ``file:line``, the key and the range, like the config's.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Annotated, Any

from pydantic import BeforeValidator, ConfigDict
from pydantic_core import PydanticCustomError

from vibsynth.errors import ConfigError
from vibsynth.settings.actuators import named_files
from vibsynth.settings.fields import SettingsModel, cross_problem, setting
from vibsynth.settings.models_config import PROFILE_NAME, ChannelPosition, VibsynthConfig, check_layout
from vibsynth.settings.paths import user_config_file
from vibsynth.settings.typed import settings_of
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
        "output channel (1-based) -> {x, y, z, name} in metres",
        allowed="a mapping {output channel 1..64: {x: m, y: m, z: m (default 0), name: text}}",
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
    """

    def __init__(self, positions: Mapping[int, ChannelPosition], name: str | None = None) -> None:
        self.name = name
        ordered = sorted(positions.items())
        self.channels = tuple(channel - 1 for channel, _ in ordered)
        self.coordinates = [(p.x, p.y, p.z) for _, p in ordered]
        self.names = [p.name for _, p in ordered]

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


def resolve_layout(config: VibsynthConfig | Any) -> Layout | None:
    """The config's layout with every position (a named layout's file is read), or None without one.

    ``config``: the typed settings, or a config (see :func:`~vibsynth.settings.typed.settings_of`).
    """
    value = settings_of(config).layout
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
        return None
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
    return None
