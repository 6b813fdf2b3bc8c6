"""Where the user's settings live: the platform config folder (nothing is read here).

Below every loader (config, actuator profiles, layouts), so each can name its user folder
without importing another loader.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["APP_NAME", "user_config_file"]

APP_NAME = "vibsynth"


def user_config_file() -> Path:
    """The platform user config file (``config.yaml`` in the platform config folder).

    Linux: ``~/.config/vibsynth/config.yaml`` (``$XDG_CONFIG_HOME``); macOS:
    ``~/Library/Application Support/vibsynth/config.yaml``; Windows:
    ``%LOCALAPPDATA%\\vibsynth\\config.yaml``.
    """
    import platformdirs  # loaded on first use: `import vibsynth.settings.config` stays light

    return Path(platformdirs.user_config_dir(APP_NAME, appauthor=False)) / "config.yaml"
