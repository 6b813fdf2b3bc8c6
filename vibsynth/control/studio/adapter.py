"""The studio for ``vibsynth serve``: its flags, its construction from the config, opening a browser.

Not in :data:`vibsynth.control.ADAPTER_MODULES`: the service builds it after the other
adapters, because it shows their status and carries extensions made in ``vibsynth/app``.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
from collections.abc import Sequence
from typing import Any

from vibsynth.control.controller import Controller
from vibsynth.control.studio.extension import StudioExtension
from vibsynth.control.studio.security import TOKEN_RULE, check_token
from vibsynth.settings.cli_args import flag_type
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["ENV_TOKEN", "add_arguments", "create", "open_in_browser"]

log = logging.getLogger(__name__)

#: Environment variable holding the studio token (when --studio-token is not given).
ENV_TOKEN = "VIBSYNTH_STUDIO_TOKEN"


def _token_flag(text: str) -> str:
    try:
        return check_token(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).split(": ", 1)[-1]) from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--no-studio``, ``--studio-port`` and ``--studio-token`` to the ``vibsynth serve`` parser."""
    group = parser.add_argument_group("studio (browser workspace)")
    group.add_argument("--no-studio", action="store_true", default=False, help="do not serve the studio")
    group.add_argument(
        "--studio-port",
        type=flag_type("studio.port"),
        default=None,
        metavar="PORT",
        help="TCP port of the studio (default: studio.port, 9571, or a free port when that one is taken; "
        "with this flag a taken port is an error; 0 = any free port)",
    )
    group.add_argument(
        "--studio-token",
        type=_token_flag,
        default=None,
        metavar="TOKEN",
        help=f"the studio's access token ({TOKEN_RULE}; default: ${ENV_TOKEN}, else random at each start)",
    )


def create(
    settings: VibsynthConfig,
    args: argparse.Namespace | None,
    controller: Controller,
    library: Any = None,
    *,
    servers: Sequence[Any] = (),
    extensions: Sequence[StudioExtension] = (),
) -> Any:
    """Build (not start) the studio server, or None when it is disabled.

    Parameters
    ----------
    settings : VibsynthConfig
        The typed settings; the studio reads its ``studio:`` section.
    args : argparse.Namespace or None
        ``no_studio``, ``studio_port``, ``studio_token`` (absent = defaults).
    controller : Controller
    library : PresetLibrary, optional
    servers : sequence
        The running control servers (OSC, MIDI): their status is shown in the studio.
    extensions : sequence of StudioExtension
        Tabs from ``vibsynth/app`` (the lab, the clip lane).

    Raises
    ------
    ParameterError
        ``$VIBSYNTH_STUDIO_TOKEN`` is not a valid token.
    """
    studio = settings.studio
    if getattr(args, "no_studio", False) or not studio.enabled:
        log.info(
            "studio disabled (%s)", "--no-studio" if getattr(args, "no_studio", False) else "studio.enabled: false"
        )
        return None
    from vibsynth.control.studio.panels import install_panels
    from vibsynth.control.studio.server import StudioServer
    from vibsynth.control.studio.status import midi_learn, status_sources

    token = getattr(args, "studio_token", None)
    if token is None and os.environ.get(ENV_TOKEN):
        token = check_token(os.environ[ENV_TOKEN], f"${ENV_TOKEN}")
    port_flag = getattr(args, "studio_port", None)
    server = StudioServer(
        controller,
        host=studio.host,
        port=port_flag if port_flag is not None else studio.port,
        token=token,
        library=library,
        extensions=extensions,
        port_fallback=port_flag is None,
        status_sources=status_sources(servers),
        learn=midi_learn,
    )
    install_panels(server, servers, settings)
    return server


def open_in_browser(url: str) -> str:
    """Open ``url`` in the user's web browser (in the background); returns a line saying what happened.

    On Linux without a display, Python's ``webbrowser`` would start a text-mode browser in
    this terminal: the line asks the user to open the URL instead.
    """
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no graphical display: open the studio URL above in a browser"
    import webbrowser

    def run() -> None:
        try:
            if not webbrowser.open_new_tab(url):
                log.warning("could not start a web browser; open the studio URL yourself")
        except Exception as exc:  # noqa: BLE001 - any browser launch failure is one warning
            log.warning("could not start a web browser (%s); open the studio URL yourself", exc)

    threading.Thread(target=run, name="vibsynth-open-browser", daemon=True).start()
    return "opening the studio in your web browser"
