"""The studio's extension tabs: the parts of ``vibsynth/app`` that add a tab to the studio.

Each module named in :data:`STUDIO_EXTENSION_MODULES` defines
``studio_extension(settings, controller, library, *, config_path=None) -> StudioExtension | None``
(None: nothing to add, e.g. disabled by the config), ``settings`` being the typed
:class:`~vibsynth.settings.models_config.VibsynthConfig` (each tab reads its own sections) and
``config_path`` the user's config file, which a tab may write a setting into (None: it may not).
The lab (issue 17) and the clip lane (issue 16) add their module here, one line each;
docs/studio.md, "Extensions", describes the contract.
"""

from __future__ import annotations

import importlib
import logging
from pathlib import Path
from typing import Any

from vibsynth.control.studio.extension import StudioExtension
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["STUDIO_EXTENSION_MODULES", "studio_extensions"]

log = logging.getLogger(__name__)

#: Modules providing ``studio_extension(settings, controller, library, *, config_path)``, in tab order.
STUDIO_EXTENSION_MODULES: tuple[str, ...] = (
    "vibsynth.app.lab.studio",
    "vibsynth.app.clips.studio",
    "vibsynth.app.lab.calibrate_tab",
)


def studio_extensions(
    settings: VibsynthConfig,
    controller: Any,
    library: Any,
    modules: tuple[str, ...] | None = None,
    *,
    config_path: Path | None = None,
) -> list[StudioExtension]:
    """The extensions the studio shows (modules missing from this installation are skipped).

    ``config_path``: the user's config file (``serve``: :func:`vibsynth.settings.config_write.user_config_path`);
    None leaves every config file alone.
    """
    out = []
    for name in STUDIO_EXTENSION_MODULES if modules is None else modules:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        extension = module.studio_extension(settings, controller, library, config_path=config_path)
        if extension is not None:
            out.append(extension)
    return out
