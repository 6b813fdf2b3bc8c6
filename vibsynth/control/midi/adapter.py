"""The MIDI adapter for ``vibsynth serve`` (contract of :mod:`vibsynth.control`): flags, ports, learn."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from typing import Any

import mido

from vibsynth.control.midi.bindings import KNOBS, MidiSettings, check_learn_knob
from vibsynth.control.midi.clipnotes import ClipNotes
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import VIRTUAL_PORT_NAME, MidiServer, _one_line, resolve_port_name, running_servers
from vibsynth.control.spatial.midi import PositionControllers
from vibsynth.errors import DeviceError
from vibsynth.settings.cli_args import flag_type
from vibsynth.settings.config_write import user_config_path
from vibsynth.settings.models_config import VibsynthConfig

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the MIDI flags of ``vibsynth serve``."""
    group = parser.add_argument_group("MIDI")
    group.add_argument(
        "--midi",
        metavar="NAME|INDEX",
        type=flag_type("midi.port"),
        default=None,
        help="open this MIDI input (name substring or index from `vibsynth devices`)",
    )
    group.add_argument(
        "--midi-virtual",
        action="store_true",
        help=f"create a virtual MIDI input named {VIRTUAL_PORT_NAME!r} (ALSA, CoreMIDI, JACK)",
    )
    group.add_argument("--no-midi", action="store_true", help="do not open any MIDI input")
    group.add_argument(
        "--learn",
        metavar="KNOB",
        choices=KNOBS,
        default=None,
        help="bind the next moved MIDI controller to KNOB (intensity|balance) and save it to the user config file",
    )


def list_inputs() -> list[str]:
    """Names of the MIDI inputs of mido's backend; empty when no backend is usable."""
    try:
        return list(mido.get_input_names())
    except Exception as exc:  # backend missing or its server not running: nothing to list
        log.debug("no MIDI inputs: %s", exc)
        return []


def create(settings: VibsynthConfig, args: argparse.Namespace, controller: Any, presets: Any) -> MidiServer | None:
    """Build (not start) the MIDI server from the typed settings and flags, or None (after one log line).

    The server gets the ``midi:`` section, the clip notes ``midi_clips:``, the position
    controllers ``sources.midi`` (the mute fade of ``knobs:`` ends notes).

    Parameters
    ----------
    settings : VibsynthConfig
    args : argparse.Namespace
        ``midi``, ``midi_virtual``, ``no_midi``, ``learn`` (absent = defaults); ``config`` (user file).
    controller : Controller
    presets : preset library or None

    Returns
    -------
    server : MidiServer or None

    Raises
    ------
    ConfigError
        A binding to a controller reserved for NRPN/RPN data.
    """
    section = settings.midi
    if getattr(args, "no_midi", False) or not section.enabled:
        log.info(
            "running without MIDI: disabled (%s)",
            "--no-midi" if getattr(args, "no_midi", False) else "midi.enabled is false",
        )
        return None
    port = getattr(args, "midi", None)
    port = section.port if port is None else port
    virtual = bool(getattr(args, "midi_virtual", False) or (port is None and section.virtual))
    if port is None and not virtual:
        log.warning("running without MIDI: no input chosen (use --midi NAME|INDEX or --midi-virtual)")
        return None
    midi = MidiSettings.from_settings(section, controller.channels, fade_ms=settings.knobs.mute_fade_ms)
    try:
        names = mido.get_input_names()
    except Exception as exc:
        log.warning("running without MIDI: the MIDI backend is not usable (%s). %s", _one_line(exc), port_help())
        return None
    if port is not None and not virtual:
        try:
            resolve_port_name(port, names)
        except DeviceError as exc:
            log.warning("running without MIDI: %s. %s", exc, port_help())
            return None
    clip_notes = ClipNotes.from_settings(settings.midi_clips, controller)  # notes -> clips
    mapper = MidiMapper(controller, midi, presets=presets, clip_notes=clip_notes)
    mapper.positions = PositionControllers.from_settings(settings.sources.midi, controller)
    server = MidiServer(
        mapper,
        port=port,
        virtual=virtual,
        config_path=user_config_path(getattr(args, "config", None)),
        reconnect_interval_s=section.reconnect_interval_s,
        tap=getattr(controller, "tap", None),
    )
    if getattr(args, "learn", None):
        server.learn(args.learn)
    return server


def port_help(platform: str | None = None, backend: str | None = None) -> str:
    """How to get MIDI ports on this platform, in one sentence for a warning (docs/midi.md, "Ports")."""
    platform = sys.platform if platform is None else platform
    backend = os.environ.get("MIDO_BACKEND", "") if backend is None else backend
    if platform.startswith("linux"):
        if "UNIX_JACK" in backend:
            return "With JACK MIDI, start jackd first (the ports are JACK's); see docs/midi.md"
        return (
            "On Linux MIDI ports come from the ALSA sequencer (/dev/snd/seq, module snd-seq); without it, "
            "use JACK MIDI: MIDO_BACKEND=mido.backends.rtmidi/UNIX_JACK with jackd running, or bridge ALSA "
            "devices into JACK with a2jmidid; see docs/midi.md"
        )
    if platform == "darwin":
        return (
            "On macOS, hardware ports appear in Audio MIDI Setup; for a software port enable the IAC Driver "
            "there, or use --midi-virtual; see docs/midi.md"
        )
    if platform.startswith("win"):
        return (
            "On Windows, connect the device or create a loopback port with loopMIDI (Windows has no virtual "
            "ports: --midi-virtual is unavailable); see docs/midi.md"
        )
    return "See docs/midi.md for how to get MIDI ports"


def learn(knob: str) -> bool:
    """Arm MIDI learn for ``knob`` on every running MIDI server (hook for OSC ``/vibsynth/learn s``).

    Returns
    -------
    armed : bool
        False when no MIDI server is running.

    Raises
    ------
    ParameterError
        Unknown knob.
    """
    check_learn_knob(knob)
    servers = active_servers()
    for server in servers:
        server.learn(knob)
    return bool(servers)


def active_servers() -> list[MidiServer]:
    """The MIDI servers started and not yet stopped in this process."""
    return running_servers()
