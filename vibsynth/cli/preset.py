"""``vibsynth preset list|show|new|from-recording|play|validate|rm``: the designer's preset workflow.

A broken preset file is reported the same way everywhere (``serve``, ``render --midi``, every
``preset`` command): one warning naming file:line when the library is read, and, when that
preset is asked for by name, an error with the same text.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path
from typing import Any

from vibsynth import __version__
from vibsynth.cli._common import file_name_argument, validate_files
from vibsynth.cli._inputs import wav_channel
from vibsynth.cli._table import Column, add_format_argument, emit, output_format
from vibsynth.errors import ParameterError, PresetError
from vibsynth.settings.cli_args import flag_type
from vibsynth.settings.config import add_config_arguments, settings_from_args
from vibsynth.settings.library import PresetLibrary, UnknownPresetError, load_library
from vibsynth.settings.models import PresetModel
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.presets import Preset, preset_to_yaml

__all__ = ["ORDER", "register"]

ORDER = 40
log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- argument types
def _float_in(low: float, high: float, unit: str = "") -> Any:
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value) or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text} is outside the allowed range [{low:g}, {high:g}]{unit}")
        return value

    return parse


def _tags(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


# --------------------------------------------------------------------------- helpers
def _library(args: argparse.Namespace) -> tuple[VibsynthConfig, PresetLibrary]:
    settings = settings_from_args(args)
    return settings, load_library(settings)  # the library warns once about each broken file


def _get(library: PresetLibrary, name: str) -> Preset:
    """The preset named on the command line: an unknown name is a usage error, a broken file a runtime one."""
    try:
        return library.get(name)
    except UnknownPresetError as exc:
        raise ParameterError(str(exc)) from None


LIST_COLUMNS = (
    Column("name", "name", name=True),
    Column("intensity", "intensity", lambda v: f"{v:.3f}"),
    Column("balance", "balance", lambda v: f"{v:+.3f}"),
    Column("program", "program", lambda v: v),
    Column("origin", "from", name=True),
    Column("tags", "tags", lambda v: ", ".join(v), name=True),
)


def _write_new(library: PresetLibrary, preset: Preset, output: Path | None, force: bool) -> Path:
    if output is not None:
        from vibsynth.settings.presets import save_preset

        target = output / f"{preset.name}.yaml" if output.is_dir() else output
        if target.exists() and not force:
            raise PresetError(f"{target}: exists already (use --force to replace it)")
        return save_preset(preset, target)
    return library.save_user(preset, overwrite=force)


#: An argparse type: a preset name (it becomes a file name, so no folders, no dots first).
preset_name = file_name_argument("preset")


def _typed_preset(**fields: Any) -> Preset:
    """A preset from values typed on the command line: a refused value is a usage error."""
    try:
        return Preset(**fields)
    except PresetError as exc:
        raise ParameterError(str(exc)) from None


# --------------------------------------------------------------------------- commands
def cmd_list(args: argparse.Namespace) -> int:
    _, library = _library(args)
    programs = {name: number for number, name in library.program_map().items()}
    presets = library.presets()
    if args.tag:
        presets = [p for p in presets if args.tag in p.tags]
    fmt = output_format(args)
    if fmt == "json":
        print(
            json.dumps(
                [
                    {**p.to_dict(), "program": programs.get(p.name), "origin": p.origin, "path": str(p.path)}
                    for p in presets
                ],
                indent=2,
            )
        )
        return 0
    if args.sort == "balance":
        presets.sort(key=lambda p: p.balance)
    elif args.sort == "program":
        presets.sort(key=lambda p: programs.get(p.name, 999))
    rows: list[dict[str, Any]] = []
    for p in presets:
        number = programs.get(p.name)
        prog = "-" if number is None else (str(number) if p.program is not None else f"{number}*")
        rows.append(
            {
                "name": p.name,
                "intensity": p.intensity,
                "balance": p.balance,
                "program": prog,
                "origin": p.origin,
                "tags": list(p.tags),
            }
        )
    if fmt == "csv":
        emit([dict(r, tags=";".join(r["tags"])) for r in rows], LIST_COLUMNS, "csv")
        return 0
    emit(rows, LIST_COLUMNS, "table")
    print(
        f"\n{len(presets)} presets; user folder: {library.user_dir}"
        + ("; * = program by name order (no program: field)" if any(r["program"].endswith("*") for r in rows) else "")
    )
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    """Check preset files the way the library reads them; one line per file, exit 1 if any is bad."""
    from vibsynth.settings.presets import load_preset

    return validate_files(
        args.files,
        load_preset,
        PresetError,
        "preset",
        lambda p: f"({p.name}: intensity {p.intensity:.3f}, balance {p.balance:+.3f})",
    )


def cmd_rm(args: argparse.Namespace) -> int:
    """Delete a user preset's file (shipped presets are read-only); a broken file can be removed too."""
    _, library = _library(args)
    try:
        target, shipped_again = library.remove_user(args.name)
    except UnknownPresetError as exc:  # shipped, no user file, unknown: the command line asked for it
        raise ParameterError(str(exc)) from None
    print(f"removed {target}" + ("; the shipped preset of that name is used again" if shipped_again else ""))
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    _, library = _library(args)
    preset = _get(library, args.name)
    if args.json:
        print(json.dumps({**preset.to_dict(), "origin": preset.origin, "path": str(preset.path)}, indent=2))
        return 0
    print(f"# {preset.origin} preset: {preset.path}")
    print(preset_to_yaml(preset, header=""), end="")
    return 0


def cmd_new(args: argparse.Namespace) -> int:
    _, library = _library(args)
    base: dict[str, Any] = {}
    if args.like:
        template = _get(library, args.like)
        base = {
            "intensity": template.intensity,
            "balance": template.balance,
            "glide_ms": template.glide_ms,
            "tags": template.tags,
            "description": template.description,
        }
    intensity = args.intensity if args.intensity is not None else base.get("intensity")
    balance = args.balance if args.balance is not None else base.get("balance")
    if intensity is None or balance is None:
        raise ParameterError("preset new: give --intensity I and --balance B (or --like NAME to start from a preset)")
    preset = _typed_preset(
        name=args.name,
        intensity=intensity,
        balance=balance,
        description=args.description if args.description is not None else base.get("description", ""),
        glide_ms=args.glide_ms if args.glide_ms is not None else base.get("glide_ms"),
        program=args.program,
        tags=tuple(args.tags) if args.tags is not None else tuple(base.get("tags", ())),
        provenance={"created_by": f"vibsynth {__version__} (preset new)"} | ({"like": args.like} if args.like else {}),
    )
    if preset.name in library and not args.force and args.output is None:
        existing = library.get(preset.name)
        if existing.origin == "shipped":
            print(f"vibsynth: note: {preset.name!r} overrides the shipped preset of that name", file=sys.stderr)
    path = _write_new(library, preset, args.output, args.force)
    print(f"wrote {path}")
    return 0


def cmd_from_recording(args: argparse.Namespace) -> int:
    from vibsynth.dsp.analysis import analyze
    from vibsynth.errors import ParameterError
    from vibsynth.formats.basis_file import default_basis, load_basis
    from vibsynth.formats.recordings import read_recording

    settings, library = _library(args)
    recording = read_recording(args.file, fs=args.rate, channel=args.channel)
    basis = load_basis(args.basis) if args.basis else default_basis()
    knobs = settings.knobs
    from vibsynth.settings.actuators import config_intensity, profile_intensity

    weighting = profile_intensity(args.profile) if args.profile else config_intensity(settings.actuator)
    try:
        result = analyze(
            recording.samples,
            fs=recording.fs,
            basis=basis,
            ceiling_db=knobs.ceiling_db,
            range_db=knobs.range_db,
            weighting=weighting,
        )
    except ParameterError as exc:
        raise PresetError(f"{recording.path}: {exc}") from None
    from vibsynth.settings.from_recording import preset_from_analysis, recording_digest

    try:
        made = preset_from_analysis(
            result,
            name=args.name or recording.path.stem,
            recording=recording.path.name,
            digest=recording_digest(recording.path.read_bytes()),
            basis_id=basis.id,
            ceiling_db=knobs.ceiling_db,
            range_db=knobs.range_db,
            created_by="preset from-recording",
            description=args.description,
            glide_ms=args.glide_ms,
            program=args.program,
            tags=args.tags or (),
            intensity_weighting=None if weighting.is_paper else weighting.describe(),
        )
    except PresetError as exc:  # a value typed on the command line
        raise ParameterError(str(exc)) from None
    for line in made.warnings:
        print(f"vibsynth: warning: {recording.path}: {line}", file=sys.stderr)
    for line in made.notes:
        print(f"vibsynth: note: {recording.path}: {line}", file=sys.stderr)
    preset = made.preset
    path = _write_new(library, preset, args.output, args.force)
    print(
        f"wrote {path}: intensity {preset.intensity:.3f}, balance {preset.balance:+.3f} "
        f"(level {result.level_db:.1f} dB, t1 {result.t1:.2f})"
    )
    return 0


def _preset_engine(settings: VibsynthConfig, library: PresetLibrary, name: str) -> Any:
    """An engine (``vibsynth.app.service.build_engine``) with the preset loaded at frame 0."""
    from vibsynth.app.service import build_engine
    from vibsynth.control.controller import Controller

    preset = _get(library, name)
    engine = build_engine(settings)
    controller = Controller.for_knobs(engine, settings.knobs, preset_resolver=library.get)
    controller.load_preset(preset.name, source="cli")
    return engine


def cmd_schema(args: argparse.Namespace) -> int:
    from vibsynth.settings.schema import schema_text

    print(schema_text("preset"), end="")
    return 0


def cmd_play(args: argparse.Namespace) -> int:
    device: Any = args.device
    if isinstance(device, str) and device.isdigit():
        device = int(device)
    settings = settings_from_args(args, extra={"audio.channels": args.channels, "audio.device": device})
    library = load_library(settings)
    preset = _get(library, args.name)
    if args.output is not None:
        from vibsynth.app.render import render
        from vibsynth.formats.wav_stream import WavStreamWriter, check_target

        try:
            check_target(args.output)
            engine = _preset_engine(settings, library, preset.name)
            total = int(round(args.seconds * engine.fs))
            with WavStreamWriter(args.output, engine.fs, engine.channels, sample_format=args.format, frames=total) as w:
                result = render(engine, total, w, block=settings.audio.block_size)
        except OSError as exc:  # missing folder, a folder, permission: one line, exit 1
            print(f"vibsynth: error: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
            return 1
        print(
            f"wrote {args.output}: {preset.name} (intensity {preset.intensity:.3f}, balance {preset.balance:+.3f}),"
            f" {args.seconds:g} s at {result.fs:g} Hz, {result.channels} channel(s)"
        )
        return 0
    import time

    from vibsynth.app.service import build_engine, open_output
    from vibsynth.control.controller import Controller

    engine = build_engine(settings)
    controller = Controller.for_knobs(engine, settings.knobs, preset_resolver=library.get)
    output = open_output(settings.audio, engine, args.device is not None)
    output.start()
    try:
        controller.load_preset(preset.name, source="cli")
        print(f"playing {preset.name} for {args.seconds:g} s on {output.describe()} (Ctrl-C stops)", file=sys.stderr)
        time.sleep(args.seconds)
        controller.panic(source="cli")
        time.sleep(max(0.05, 2 * settings.knobs.mute_fade_ms / 1000.0))
    finally:
        output.stop()
    return 0


# --------------------------------------------------------------------------- parser
def register(subparsers: Any) -> None:
    """Add ``vibsynth preset ...``."""
    parser = subparsers.add_parser(
        "preset",
        help="list, show, create and play presets",
        description="Presets: named textures in YAML files (docs/presets.md). "
        "User presets override shipped ones of the same name.",
    )
    sub = parser.add_subparsers(dest="preset_command", metavar="ACTION", required=True)

    p = sub.add_parser("list", help="table of presets: name, intensity, balance, program, tags")
    add_config_arguments(p)
    p.add_argument("--sort", choices=("name", "balance", "program"), default="name")
    p.add_argument("--tag", help="only presets with this tag")
    add_format_argument(p)
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("show", help="print one preset (YAML) and its file")
    add_config_arguments(p)
    p.add_argument("name")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_show)

    def add_common_new(p: argparse.ArgumentParser) -> None:
        p.add_argument("--glide-ms", type=flag_type("glide_ms", PresetModel), help="glide when applied (ms)")
        p.add_argument("--program", type=flag_type("program", PresetModel), help="MIDI program number 0..127")
        p.add_argument("--tags", type=_tags, help="comma-separated tags")
        p.add_argument("--description")
        p.add_argument("-o", "--output", type=Path, help="write here instead of the user preset folder")
        p.add_argument("--force", action="store_true", help="replace an existing file")

    p = sub.add_parser("new", help="create a user preset")
    add_config_arguments(p)
    p.add_argument("name", type=preset_name)
    p.add_argument("--balance", type=flag_type("balance", PresetModel), help="balance (knob units)")
    p.add_argument("--intensity", type=flag_type("intensity", PresetModel), help="intensity 0..1")
    p.add_argument("--like", metavar="PRESET", help="start from an existing preset's values")
    add_common_new(p)
    p.set_defaults(func=cmd_new)

    p = sub.add_parser("from-recording", help="analyse a recording and save it as a preset (with provenance)")
    add_config_arguments(p)
    p.add_argument("file", type=Path, help="recording: .wav, or .csv/.txt with --rate")
    p.add_argument("--name", type=preset_name, help="preset name (default: the file name)")
    p.add_argument("--rate", type=_float_in(2400, 768000, " Hz"), help="sample rate of a CSV/TXT recording (Hz)")
    p.add_argument(
        "--channel", type=wav_channel, default=0, metavar="N", help="channel of a multi-channel WAV (1 = the first)"
    )
    p.add_argument("--basis", type=Path, help="spectral basis YAML (default: the shipped basis)")
    p.add_argument(
        "--profile",
        metavar="NAME",
        help="measure intensity as on this actuator profile's device (its calibrated weighting; default: the "
        "config's actuator.profile, whose weighting the engine's knob uses)",
    )
    add_common_new(p)
    p.set_defaults(func=cmd_from_recording)

    p = sub.add_parser("play", help="play a preset through the configured output, or render it to a WAV (-o)")
    add_config_arguments(p)
    p.add_argument("name")
    p.add_argument("--seconds", type=_float_in(0.01, 3600, " s"), default=3.0)
    p.add_argument("-o", "--output", type=Path, help="write a WAV file instead of playing")
    p.add_argument("--format", choices=("float32", "pcm16"), default="float32", help="WAV sample format")
    p.add_argument("--device", help="output device (name substring or index; default: audio.device)")
    p.add_argument("--channels", type=flag_type("audio.channels"), help="actuator channels (default: audio.channels)")
    p.set_defaults(func=cmd_play)

    p = sub.add_parser("validate", help="check preset files (errors name file, line, key, value, range)")
    p.add_argument("files", nargs="+", type=Path, metavar="FILE.yaml")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("rm", help="delete a user preset (shipped presets are read-only)")
    add_config_arguments(p)
    p.add_argument("name", type=preset_name)
    p.set_defaults(func=cmd_rm)

    p = sub.add_parser("schema", help="print the JSON Schema of a preset file (editor completion; docs/presets.md)")
    p.set_defaults(func=cmd_schema)
