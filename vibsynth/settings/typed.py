"""The typed settings of plain config data: validated against the model, no file read.

Below the loader (:mod:`~vibsynth.settings.config`), which builds the model once; everything
after it takes the model or its sections.
"""

from __future__ import annotations

from typing import Any

from vibsynth.errors import ConfigError
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.validation import FixedLocator, model_spec, validate

__all__ = ["settings_of"]


def settings_of(config: Any) -> VibsynthConfig:
    """The typed settings of a config's current ``.data`` (or of a plain config dict), validated now.

    A :class:`~vibsynth.settings.models_config.VibsynthConfig` is returned as it is. For anything
    with a ``.data`` dict (a :class:`~vibsynth.settings.config.Config`, a test's namespace) or a
    plain dict, what is in the data now is validated; missing keys take their defaults. No file
    named by the config (layout, actuator profile) is looked up.

    Raises
    ------
    ConfigError
        ``config: osc.port = 70000: outside the allowed range [0, 65535]``.
    """
    if isinstance(config, VibsynthConfig):
        return config
    data = getattr(config, "data", config)
    result: VibsynthConfig = validate(model_spec(VibsynthConfig), data or {}, FixedLocator("config"), ConfigError)
    return result
