"""Configuration: layered YAML (minimal version; full validation and layering in issue 6).

API contract used by the rest of the package:

* ``load_config(path=None, *, overrides=None) -> Config``
* ``Config.data``: nested dict with every key of ``vibsynth/data/config/default.yaml``
* ``Config.section(name) -> dict``
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import yaml

from vibsynth.errors import ConfigError

__all__ = ["Config", "load_config", "default_config_data"]


def default_config_data() -> dict[str, Any]:
    text = resources.files("vibsynth.data").joinpath("config/default.yaml").read_text(encoding="utf-8")
    return yaml.safe_load(text)


def _merge(base: dict[str, Any], extra: Mapping[str, Any]) -> None:
    for key, value in extra.items():
        if isinstance(value, Mapping) and isinstance(base.get(key), dict):
            _merge(base[key], value)
        else:
            base[key] = copy.deepcopy(value)


@dataclass
class Config:
    data: dict[str, Any]
    sources: dict[str, str] = field(default_factory=dict)

    def section(self, name: str) -> dict[str, Any]:
        return self.data[name]


def load_config(path: str | Path | None = None, *, overrides: Mapping[str, Any] | None = None) -> Config:
    data = default_config_data()
    if path is not None:
        try:
            user = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ConfigError(f"{path}: {exc}") from None
        _merge(data, user)
    if overrides:
        _merge(data, overrides)
    return Config(data=data)
