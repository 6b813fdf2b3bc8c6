"""``vibsynth calibrate response``: measure an actuator through a sensor, write its profile (docs/calibration.md)."""

from __future__ import annotations

import argparse
import logging
import sys

from vibsynth.cli._numbers import integer_in, number_in

ORDER = 14

log = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from vibsynth.settings.cli_args import flag_type
    from vibsynth.settings.config import add_config_arguments

    p = subparsers.add_parser(
        "calibrate",
        help="measure an actuator's response with a sensor and write its profile",
        description="Calibration of actuators (docs/calibration.md).",
    )
    sub = p.add_subparsers(dest="calibrate_command", metavar="ACTION", required=True)
    r = sub.add_parser(
        "response",
        help="play swept sines through an output channel, record a sensor, write an actuator profile",
        description="Plays a second of silence then exponential sweeps (5 Hz-2 kHz) on one output channel (or every "
        "channel, one after the other), records the sensor on --input DEVICE:CH, measures the loop's latency, checks "
        "clipping, a response lost mid-run, signal, noise, SNR and repeatability, and writes an absolute actuator "
        "profile with its provenance. A failed check prints one message and writes nothing.",
    )
    which = r.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--channel", type=integer_in(1, None, what="--channel"), metavar="N", help="output channel (1-based)"
    )
    which.add_argument(
        "--channels", choices=["all"], help="measure every channel of audio.channels, one after the other"
    )
    r.add_argument(
        "--input", required=True, metavar="DEVICE:CH", help="the sensor's input: device name or index, 1-based channel"
    )
    r.add_argument(
        "-o",
        "--output",
        metavar="PROFILE",
        help="profile name (written to the user actuator folder) or FILE.yaml; several channels add -chN "
        "(default: measured)",
    )
    r.add_argument(
        "--level",
        type=number_in(-60.0, 0.0, unit="dBFS"),
        default=-12.0,
        metavar="DB",
        help="peak level of the sweep, dBFS (default -12)",
    )
    r.add_argument(
        "--sweeps", type=integer_in(1, 20, what="--sweeps"), default=3, metavar="N", help="sweeps (default 3)"
    )
    r.add_argument(
        "--seconds",
        type=number_in(1.0, 30.0, unit="s"),
        default=4.0,
        metavar="S",
        help="one sweep's length (default 4)",
    )
    r.add_argument(
        "--device",
        type=flag_type("audio.device"),
        metavar="NAME|INDEX",
        help="audio output device (default audio.device; see `vibsynth devices`)",
    )
    add_config_arguments(r)
    r.set_defaults(func=run_response)


def run_response(args: argparse.Namespace) -> int:
    from vibsynth import __version__
    from vibsynth.app.calibrate import measure_channels, write_profiles
    from vibsynth.settings.actuators import user_profile_dir
    from vibsynth.settings.config import settings_from_args

    settings = settings_from_args(args, extra={"audio.device": args.device})
    channels = list(range(1, settings.audio.channels + 1)) if args.channels == "all" else [args.channel]

    def say(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    results = measure_channels(
        settings,
        channels=channels,
        input_spec=args.input,
        level_db=args.level,
        sweeps=args.sweeps,
        seconds=args.seconds,
        progress=say,
    )
    paths = write_profiles(results, args.output, user_dir=user_profile_dir(), version=__version__)
    for r, path in zip(results, paths, strict=True):
        m = r.measurement
        fs = r.plan.fs
        print(
            f"channel {r.channel}: latency {1000 * r.latency_frames / fs:.2f} ms, SNR >= {m.snr_in(20, 800):.1f} dB "
            f"(20-800 Hz), sweeps agree within {m.repeatability_db:.2f} dB, peak {m.response_db.max():.1f} dB at "
            f"{m.freqs[int(m.response_db.argmax())]:.0f} Hz -> {path}"
        )
    if len(paths) > 1 and all(p.parent == user_profile_dir() for p in paths):
        pattern = paths[0].stem.removesuffix(f"-ch{results[0].channel}") + "-ch{n}"
        print(
            f"serve every channel with its own profile: --set 'actuator.channel_profiles={pattern}' "
            "(docs/calibration.md)"
        )
    return 0
