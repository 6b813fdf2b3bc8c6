"""Actuator profiles: named frequency responses (shipped and user files) a config can name."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from vibsynth.errors import ConfigError
from vibsynth.settings.config import _PROFILE_NAME, Config, _close, _fmt, _points, boolean, string, user_config_file
from vibsynth.settings.yamldoc import read_yaml_file

ACTUATOR_RESOURCE = "config/actuators"
_PROFILE_KEYS = {
    "name": string(pattern=_PROFILE_NAME, what="a profile name (letters, digits, . _ -)"),
    "description": string(what="text"),
    "example": boolean(),
    "source": string(what="text"),
    "response": _points("Hz", 0, True, -60, 60, 1, False, "response points"),
}


def user_profile_dir() -> Path:
    """Folder for user actuator profiles: ``actuators/`` in the platform config folder."""
    return user_config_file().parent / "actuators"


def actuator_profiles() -> dict[str, str]:
    """Available actuator profiles: name -> file (user profiles override shipped ones)."""
    out: dict[str, str] = {}
    shipped = resources.files("vibsynth.data").joinpath(ACTUATOR_RESOURCE)
    if shipped.is_dir():
        for item in shipped.iterdir():
            if item.name.endswith(".yaml"):
                out[item.name[:-5]] = str(item)
    user = user_profile_dir()
    if user.is_dir():
        for item in user.glob("*.yaml"):
            out[item.stem] = str(item)
    return out


def load_actuator_profile(name: str) -> dict[str, Any]:
    """Read and validate one actuator profile by name.

    Returns
    -------
    profile : dict
        ``name``, ``description``, ``example`` (True for illustrative profiles), ``response`` [[Hz, dB], ...].
    """
    profiles = actuator_profiles()
    if name not in profiles:
        raise ConfigError(
            f"unknown actuator profile {name!r}{_close(name, list(profiles))} "
            f"(available: {', '.join(sorted(profiles))})"
        )
    doc = read_yaml_file(profiles[name], what="an actuator profile")
    if not isinstance(doc.data, dict):
        raise ConfigError(f"{doc.origin}: an actuator profile must be a mapping with name, description, response")
    for key, value in doc.data.items():
        spec = _PROFILE_KEYS.get(key)
        if spec is None:
            raise ConfigError(f"{doc.where((str(key),))}: unknown key {key!r} (allowed: {', '.join(_PROFILE_KEYS)})")
        reason = spec.check(value)
        if reason:
            raise ConfigError(f"{doc.where((str(key),))}: {key} = {_fmt(value)}: {reason} (allowed: {spec.allowed})")
    if "response" not in doc.data:
        raise ConfigError(f"{doc.origin}: missing key 'response' ([[Hz, dB], ...])")
    if doc.data.get("name", name) != name:
        raise ConfigError(
            f"{doc.where(('name',))}: name = {doc.data['name']!r} does not match the file name {name}.yaml"
        )
    return {
        "name": name,
        "description": doc.data.get("description", ""),
        "example": doc.data.get("example", False),
        "source": doc.data.get("source", ""),
        "response": doc.data["response"],
        "file": doc.origin,
    }


def resolve_actuator_response(config: Config) -> list[tuple[float, float]]:
    """The actuator response points ``[(Hz, dB), ...]`` to equalise for.

    An explicit ``actuator.response`` wins; else the points of ``actuator.profile``;
    else (profile null) an empty list (flat).
    """
    actuator = config.section("actuator")
    if actuator.get("response") is not None:
        return [(float(hz), float(db)) for hz, db in actuator["response"]]
    if actuator.get("profile") is None:
        return []
    return [(float(hz), float(db)) for hz, db in load_actuator_profile(actuator["profile"])["response"]]
