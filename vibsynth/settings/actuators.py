"""Actuator profiles: named frequency responses (shipped and user files) a config can name.

A profile file is checked against :class:`~vibsynth.settings.models_preset.ActuatorProfileModel`
(keys, ranges and help text defined there); errors name ``file:line``, the key and the range.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from pydantic_core import PydanticCustomError

from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, IntensityWeighting, profile_weighting
from vibsynth.errors import ConfigError, ParameterError
from vibsynth.settings.fields import cross_problem
from vibsynth.settings.models_config import Actuator, VibsynthConfig
from vibsynth.settings.models_preset import ActuatorProfileModel
from vibsynth.settings.paths import user_config_file
from vibsynth.settings.validation import did_you_mean, model_spec, validate
from vibsynth.settings.yamldoc import read_yaml_file

__all__ = [
    "ACTUATOR_RESOURCE",
    "named_files",
    "user_profile_dir",
    "actuator_profiles",
    "load_actuator_profile",
    "resolve_actuator_response",
    "resolve_actuator_absolute",
    "profile_problem",
    "profile_rate_problem",
    "profile_intensity",
    "config_intensity",
]

ACTUATOR_RESOURCE = "config/actuators"


def user_profile_dir() -> Path:
    """Folder for user actuator profiles: ``actuators/`` in the platform config folder."""
    return user_config_file().parent / "actuators"


def shipped_profile_dir() -> Path:
    """Folder of the actuator profiles shipped as package data."""
    return Path(str(resources.files("vibsynth.data").joinpath(ACTUATOR_RESOURCE)))


def named_files(shipped: Any, user: Path) -> dict[str, str]:
    """The ``NAME.yaml`` files of a shipped folder (``resources.files(...)``) and a user folder: name -> file.

    A user file overrides the shipped file of the same name; missing folders hold nothing.
    """
    out: dict[str, str] = {}
    if shipped.is_dir():
        for item in shipped.iterdir():
            if item.name.endswith(".yaml"):
                out[item.name[:-5]] = str(item)
    if user.is_dir():
        for path in user.glob("*.yaml"):
            out[path.stem] = str(path)
    return out


def actuator_profiles() -> dict[str, str]:
    """Available actuator profiles: name -> file (user profiles override shipped ones)."""
    return named_files(resources.files("vibsynth.data").joinpath(ACTUATOR_RESOURCE), user_profile_dir())


def read_actuator_profile(path: str | Path, name: str | None = None) -> ActuatorProfileModel:
    """Read and validate one actuator profile file (``name``: the expected name, default the file stem)."""
    p = Path(path)
    name = p.stem if name is None else name
    doc = read_yaml_file(p, what="an actuator profile")
    if not isinstance(doc.data, dict):
        raise ConfigError(f"{doc.origin}: an actuator profile must be a mapping with name, description, response")
    model: ActuatorProfileModel = validate(model_spec(ActuatorProfileModel), doc.data, doc, ConfigError)
    if model.name is not None and model.name != name:
        raise ConfigError(f"{doc.where(('name',))}: name = {model.name!r} does not match the file name {name}.yaml")
    return model


def load_actuator_profile(name: str) -> dict[str, Any]:
    """Read and validate one actuator profile by name.

    Returns
    -------
    profile : dict
        ``name``, ``description``, ``example`` (True for illustrative profiles), ``source``,
        ``response`` [[Hz, dB], ...], ``file``; a measured profile's ``absolute``, ``rate``,
        ``weighting``, ``band_hz`` and ``provenance`` (None where the file has none).
    """
    profiles = actuator_profiles()
    if name not in profiles:
        raise ConfigError(
            f"unknown actuator profile {name!r}{did_you_mean(name, list(profiles))} "
            f"(available: {', '.join(sorted(profiles))})"
        )
    model = read_actuator_profile(profiles[name], name)
    return {
        "name": name,
        "description": model.description,
        "example": model.example,
        "source": model.source,
        "response": [list(point) for point in model.response],
        "file": profiles[name],
        "absolute": model.absolute,
        "rate": model.rate,
        "weighting": None if model.weighting is None else [list(p) for p in model.weighting],
        "band_hz": None if model.band_hz is None else list(model.band_hz),
        "provenance": model.provenance,
    }


def profile_rate_problem(profile: dict[str, Any], rate: int) -> str | None:
    """Why a measured profile does not fit an engine at ``rate`` Hz (measured at another rate), or None.

    The converters' filters, the latency and the sensor chain's response were those of the
    measuring rate; a profile measured at another rate is measured again rather than trusted.
    """
    measured = profile.get("rate")
    if measured is None or int(measured) == int(rate):
        return None
    return (
        f"actuator profile {profile['name']!r} was measured at {measured} Hz but audio.rate is {rate} Hz: measure it "
        f"again at {rate} Hz (vibsynth calibrate response --set audio.rate={rate} ...) or set audio.rate: {measured}"
    )


def profile_problem(config: VibsynthConfig) -> PydanticCustomError | None:
    """``actuator.profile`` names no profile file (when no explicit ``actuator.response`` wins), or None.

    One of the loader's file checks (:data:`~vibsynth.settings.models_config.FILE_CHECKS`).
    """
    profile = config.actuator.profile
    if profile is None or config.actuator.response is not None:
        return None
    names = actuator_profiles()
    if profile in names:
        try:
            loaded = load_actuator_profile(profile)
        except ConfigError:
            return None  # a broken profile file says so, with its line, where it is read
        message = profile_rate_problem(loaded, config.audio.rate)
        return None if message is None else cross_problem(message, "actuator.profile", "audio.rate")
    return cross_problem(
        f"actuator.profile = {profile!r}: no such profile (allowed: "
        f"{', '.join(sorted(names)) or 'none found'}, or null; user profiles go in {user_profile_dir()})",
        "actuator.profile",
    )


def profile_intensity(name: str) -> IntensityWeighting:
    """What intensity means on profile ``name``'s device: its calibrated weighting, else the paper's band.

    Raises
    ------
    ConfigError
        No such profile, or a broken one (its weighting or band).
    """
    profile = load_actuator_profile(name)
    try:
        return profile_weighting(
            profile["response"], profile["weighting"], profile["band_hz"], source=f"profile {name}"
        )
    except ParameterError as exc:
        raise ConfigError(f"{profile['file']}: {exc}") from None


def config_intensity(actuator: Actuator) -> IntensityWeighting:
    """What the intensity knob's level means for the typed ``actuator:`` section (explicit points: the paper's band)."""
    if actuator.response is not None or actuator.profile is None:
        return PAPER_WEIGHTING
    return profile_intensity(actuator.profile)


def resolve_actuator_absolute(actuator: Actuator) -> bool:
    """Whether the response :func:`resolve_actuator_response` gives for ``actuator:`` is a measured profile's."""
    if actuator.response is not None or actuator.profile is None:
        return False
    return bool(load_actuator_profile(actuator.profile)["absolute"])


def resolve_actuator_response(actuator: Actuator) -> list[tuple[float, float]]:
    """The actuator response points ``[(Hz, dB), ...]`` to equalise for, of the typed ``actuator:`` section.

    An explicit ``actuator.response`` wins; else the points of ``actuator.profile``;
    else (profile null) an empty list (flat).
    """
    if actuator.response is not None:
        return [(float(hz), float(db)) for hz, db in actuator.response]
    if actuator.profile is None:
        return []
    return [(float(hz), float(db)) for hz, db in load_actuator_profile(actuator.profile)["response"]]
