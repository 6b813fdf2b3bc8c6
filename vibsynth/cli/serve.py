"""``vibsynth serve``: run the real-time engine on an audio output, with OSC/MIDI control."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from vibsynth.cli._common import finite_float, number_in
from vibsynth.settings.cli_args import flag_choices, flag_type

if TYPE_CHECKING:
    from vibsynth.settings.models_config import VibsynthConfig

ORDER = 5

HELP = """\
Run the haptic texture engine on an audio output (the actuator) until Ctrl-C.

It starts silent; make it vibrate with e.g.
  vibsynth send /vibsynth/intensity 0.5     (OSC, in another terminal)
or start with --intensity 0.5 [--balance 1] or --preset NAME.

Outputs: auto (PortAudio, else a silent null output with a warning), sounddevice
(PortAudio; an error if it cannot be opened), null (no sound card), wav (-o FILE
--seconds N: rendered faster than real time).

--follow DEVICE[:CH,...], monitor or FILE (WAV, FLAC, Ogg, MP3...) follows a sound or vibration live: the
texture tracks its level, brightness and onsets (--follow-mode vibration|audio,
--follow-focus all|effects|bass|beat; docs/follow.md).

A lost audio device (unplugged, JACK server stopped) does not stop the service:
OSC/MIDI keep working, /status and the status line say "device lost: <reason>",
and it retries every 0.25-2 s until the device is back, with the same knobs.
SIGTERM/Ctrl-C exit (code 0) within 2 s in every state.
"""


#: serve --seconds: stop after this long (no upper bound beyond a day).
_seconds = number_in(0.0, 86400.0, unit="s", low_open=True)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "serve",
        help="run the real-time engine (audio output + OSC/MIDI control)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(p)
    p.set_defaults(func=run)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``vibsynth serve`` (``vibsynth studio`` takes the same)."""
    from vibsynth.settings.config import add_config_arguments

    add_config_arguments(p)
    p.add_argument("--preset", metavar="NAME", help="start with this preset")
    p.add_argument("--balance", type=finite_float, metavar="B", help="initial balance (knob units)")
    p.add_argument(
        "--intensity",
        type=flag_type("knobs.initial_intensity"),
        metavar="I",
        help="initial intensity 0..1 (default 0: silent)",
    )
    p.add_argument(
        "--channels", type=flag_type("audio.channels"), metavar="N", help="actuator channels (default audio.channels)"
    )
    p.add_argument(
        "--output",
        choices=flag_choices("audio.backend"),
        default=None,
        help="output backend (default audio.backend, auto)",
    )
    p.add_argument(
        "--device",
        type=flag_type("audio.device"),
        metavar="NAME|INDEX",
        help="audio output device (name substring or index; see `vibsynth devices`)",
    )
    p.add_argument("--seconds", type=_seconds, metavar="S", help="stop after S seconds")
    p.add_argument("-o", dest="wav", metavar="FILE.wav", help="file of the wav output")
    _add_follow_arguments(p)
    from vibsynth.control import adapter_modules

    for module in adapter_modules():
        module.add_arguments(p)
    from vibsynth.control.studio import adapter as studio_adapter

    studio_adapter.add_arguments(p)
    from vibsynth.control.oscquery import adapter as oscquery_adapter

    oscquery_adapter.add_arguments(p)


def _add_follow_arguments(p: argparse.ArgumentParser) -> None:
    """``--follow DEVICE[:CH,...]|FILE.wav``, ``--follow-mode``, ``--follow-focus`` (the ``follow:`` section)."""
    group = p.add_argument_group("follow (docs/follow.md)")
    group.add_argument(
        "--follow",
        type=flag_type("follow.device"),
        metavar="DEVICE[:CH,...]|monitor|FILE.wav",
        help="follow this input live: a device (name substring or index, then 1-based inputs; on JACK, "
        "serve's own in_N ports), 'monitor' (what the system plays: JACK playback feeds, a PulseAudio/PipeWire "
        "monitor, a WASAPI loopback) or a sound file (WAV, FLAC, Ogg, MP3...) played in step with the output "
        "(default: follow.device when follow.enabled)",
    )
    group.add_argument(
        "--follow-mode", choices=flag_choices("follow.mode"), default=None, help="default follow.mode (vibration)"
    )
    group.add_argument(
        "--follow-focus",
        choices=flag_choices("follow.focus"),
        default=None,
        help="audio mode: what shakes (default follow.focus, all)",
    )


def _settings(args: argparse.Namespace) -> VibsynthConfig:
    """The typed settings of a ``serve`` (file, environment, ``--set`` and the flags), built once here."""
    extra = {"audio.channels": args.channels, "audio.backend": args.output, "audio.device": args.device}
    extra["layout"] = getattr(args, "layout", None)  # --layout (control/spatial/adapter.py)
    follow = getattr(args, "follow", None)
    extra.update({"follow.device": follow, "follow.enabled": True if follow is not None else None})
    extra.update(
        {"follow.mode": getattr(args, "follow_mode", None), "follow.focus": getattr(args, "follow_focus", None)}
    )
    if args.wav and args.output is None:
        extra["audio.backend"] = "wav"
    from vibsynth.settings.config import settings_from_args

    return settings_from_args(args, extra=extra)


def run(args: argparse.Namespace) -> int:
    from vibsynth.app.allocator import tune_allocator

    tune_allocator()  # before serve's threads start: a long run's RSS follows what is in use
    from vibsynth.app.service import serve

    settings = _settings(args)
    try:
        if settings.audio.backend == "wav":
            _check_wav_output(args)
        # The CLI owns the process: SIGTERM/SIGINT exit (code 0) on time even if a device hangs.
        return serve(settings, args, owns_process=True)
    except OSError as exc:  # the wav output's file: refused at the start, or failed while writing
        where = f"{exc.filename}: " if exc.filename is not None else ""
        print(f"vibsynth: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1


def _check_wav_output(args: argparse.Namespace) -> None:
    """Refuse a wav output that cannot be written before the (slow) bank build."""
    from vibsynth.errors import ParameterError
    from vibsynth.formats.wav_stream import check_target

    if not args.wav:
        raise ParameterError("the wav output needs a file: -o FILE.wav")
    if args.seconds is None:
        raise ParameterError("the wav output needs a duration: --seconds N")
    check_target(args.wav, writable=True)
