"""``vibsynth clip list|show|validate|import|export|from-audio``: haptic clips on the command line (docs/clips.md).

A broken clip file is reported the same way everywhere: one warning naming file:line when the
library is read and, when that clip is asked for by name, an error with the same text.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from vibsynth.cli._clip_play import add_clip_play_parsers
from vibsynth.cli._common import file_name_argument, validate_files
from vibsynth.cli._follow import add_from_audio_parser
from vibsynth.cli._table import Column, add_format_argument, emit, output_format
from vibsynth.errors import ClipError, ParameterError
from vibsynth.formats.haptic_design import HapticDesign
from vibsynth.settings.clip_convert import ClipMapping, clip_from_design, clip_name, design_from_clip
from vibsynth.settings.clips import Clip, ClipLibrary, UnknownClipError, clip_to_yaml, load_clip, load_clip_library
from vibsynth.settings.config import add_config_arguments, settings_from_args
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["ORDER", "register", "IMPORTERS", "EXPORTERS", "clip_by_name_or_path"]

ORDER = 42

clip_name_argument = file_name_argument("clip")


def _read_ahap(path: Path) -> HapticDesign:
    from vibsynth.formats.ahap import read_ahap

    return read_ahap(path)


def _read_haptic(path: Path) -> HapticDesign:
    from vibsynth.formats.meta_haptic import read_meta_haptic

    return read_meta_haptic(path)


#: File kind -> reader; the kind is the file's suffix unless ``--from`` names it.
IMPORTERS = {"ahap": _read_ahap, "haptic": _read_haptic}


# --------------------------------------------------------------------------- helpers
def _library(args: argparse.Namespace) -> tuple[VibsynthConfig, ClipLibrary]:
    settings = settings_from_args(args)
    return settings, load_clip_library(settings)  # the library warns once about each broken file


def _get(library: ClipLibrary, name: str) -> Clip:
    """The clip named on the command line: an unknown name is a usage error, a broken file a runtime one."""
    try:
        return library.get(name)
    except UnknownClipError as exc:
        raise ParameterError(str(exc)) from None


def _summary(clip: Clip) -> str:
    loop = f", loop {clip.loop[0]:g}-{clip.loop[1]:g} ms" if clip.loop else ""
    return f"{clip.duration_ms:g} ms, {len(clip.keyframes)} keyframes, {len(clip.transients)} transients{loop}"


LIST_COLUMNS = (
    Column("name", "name", name=True),
    Column("duration_ms", "ms", lambda v: f"{v:g}"),
    Column("keyframes", "keyframes"),
    Column("transients", "transients"),
    Column("loop", "loop", lambda v: "-" if v is None else f"{v[0]:g}-{v[1]:g}"),
    Column("origin", "from", name=True),
    Column("tags", "tags", lambda v: ", ".join(v), name=True),
)


# --------------------------------------------------------------------------- commands
def cmd_list(args: argparse.Namespace) -> int:
    _, library = _library(args)
    clips = [c for c in library.clips() if not args.tag or args.tag in c.tags]
    fmt = output_format(args)
    if fmt == "json":
        print(json.dumps([{**c.to_dict(), "origin": c.origin, "path": str(c.path)} for c in clips], indent=2))
        return 0
    rows: list[dict[str, Any]] = [
        {
            "name": c.name,
            "duration_ms": c.duration_ms,
            "keyframes": len(c.keyframes),
            "transients": len(c.transients),
            "loop": c.loop,
            "origin": c.origin,
            "tags": list(c.tags),
        }
        for c in clips
    ]
    if fmt == "csv":
        emit(
            [
                dict(r, tags=";".join(r["tags"]), loop="" if r["loop"] is None else "{:g}-{:g}".format(*r["loop"]))
                for r in rows
            ],
            LIST_COLUMNS,
            "csv",
        )
        return 0
    emit(rows, LIST_COLUMNS, "table")
    print(f"\n{len(clips)} clips; user folder: {library.user_dir}")
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    _, library = _library(args)
    clip = _get(library, args.name)
    if args.json:
        print(json.dumps({**clip.to_dict(), "origin": clip.origin, "path": str(clip.path)}, indent=2))
        return 0
    print(f"# {clip.origin} clip: {clip.path} ({_summary(clip)})")
    print(clip_to_yaml(clip, header=""), end="")
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    """Check clip files the way the library reads them; one line per file, exit 1 if any is bad."""
    return validate_files(args.files, load_clip, ClipError, "clip", lambda c: f"({c.name}: {_summary(c)})")


def _kind(path: Path, given: str | None) -> str:
    kind = given or path.suffix.lower().lstrip(".")
    if kind not in IMPORTERS:
        raise ParameterError(
            f"{path}: cannot tell the format from the name; expected FILE.ahap or FILE.haptic (or --from ahap|haptic)"
        )
    return kind


def cmd_import(args: argparse.Namespace) -> int:
    settings, library = _library(args)
    path: Path = args.file
    design = IMPORTERS[_kind(path, args.source)](path)
    if design.ignored:
        print(f"vibsynth: warning: {path}: ignored: {'; '.join(design.ignored)}", file=sys.stderr)
    to_file = args.output is not None and not args.output.is_dir()
    name = args.name or clip_name((args.output if to_file else path).stem)  # a clip's name is its file's stem
    clip = clip_from_design(design, name, ClipMapping.from_settings(settings))
    if args.output is not None:
        from vibsynth.settings.clips import save_clip

        target = args.output / f"{name}.yaml" if args.output.is_dir() else args.output
        if target.exists() and not args.force:
            raise ClipError(f"{target}: exists already (use --force to replace it)")
        written = save_clip(clip, target)
    else:
        written = library.save_user(clip, overwrite=args.force)
    print(f"wrote {written}: {_summary(clip)}")
    return 0


def clip_by_name_or_path(library: ClipLibrary, ref: str) -> Clip:
    """A clip by name, or a clip file given by path (``something.yaml``, or anything with a folder in it)."""
    if "/" in ref or (ref.endswith(".yaml") and Path(ref).is_file()):
        return load_clip(ref)
    return _get(library, ref)


def _ahap_text(design: HapticDesign, clip: Clip) -> str:
    from vibsynth.formats.ahap import ahap_text

    return ahap_text(design)


def _haptic_text(design: HapticDesign, clip: Clip) -> str:
    from vibsynth.formats.meta_haptic import meta_haptic_text

    return meta_haptic_text(design, source=f"vibsynth clip {clip.name}")


#: Export format -> (text writer, name in messages); the suffix is the format's name.
EXPORTERS = {"ahap": (_ahap_text, "AHAP"), "haptic": (_haptic_text, "Meta .haptic")}


def cmd_export(args: argparse.Namespace) -> int:
    from vibsynth.formats.files import atomic_write

    settings, library = _library(args)
    clip = clip_by_name_or_path(library, args.name)
    design = design_from_clip(clip, ClipMapping.from_settings(settings))
    to_text, label = EXPORTERS[args.format]
    text = to_text(design, clip)
    if args.output is not None and str(args.output) == "-":
        sys.stdout.write(text)
        _note_decay(clip, label)
        return 0
    target = args.output if args.output is not None else Path(f"{clip.name}.{args.format}")
    if target.is_dir():
        target = target / f"{clip.name}.{args.format}"
    if target.exists() and not args.force:
        raise ClipError(f"{target}: exists already (use --force to replace it)")
    try:
        atomic_write(target, text)
    except OSError as exc:
        raise ClipError(f"{target}: cannot write ({exc.strerror})") from None
    print(f"wrote {target}: {_summary(clip)} as {label}")
    _note_decay(clip, label)
    return 0


def _note_decay(clip: Clip, label: str) -> None:
    if clip.transients:
        print(
            f"vibsynth: note: {clip.name}: {label} transients have a fixed shape; their decay_ms is not exported",
            file=sys.stderr,
        )


def cmd_schema(args: argparse.Namespace) -> int:
    from vibsynth.settings.schema import schema_text

    print(schema_text("clip"), end="")
    return 0


# --------------------------------------------------------------------------- parser
def register(subparsers: Any) -> None:
    """Add ``vibsynth clip ...``."""
    parser = subparsers.add_parser(
        "clip",
        help="haptic clips: list, show, validate, import/export AHAP and Meta .haptic, from-audio, play",
        description="Haptic clips: timelines of the two knobs in YAML files (docs/clips.md). "
        "User clips override shipped ones of the same name.",
    )
    sub = parser.add_subparsers(dest="clip_command", metavar="ACTION", required=True)

    p = sub.add_parser("list", help="table of clips: name, duration, keyframes, transients, loop, tags")
    add_config_arguments(p)
    p.add_argument("--tag", help="only clips with this tag")
    add_format_argument(p)
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("show", help="print one clip (YAML) and its file")
    add_config_arguments(p)
    p.add_argument("name")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("validate", help="check clip files (errors name file, line, key, value, range)")
    p.add_argument("files", nargs="+", type=Path, metavar="FILE.yaml")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser(
        "import",
        help="turn an AHAP or Meta .haptic file into a clip (user clip folder, or -o)",
        description="Import an Apple Core Haptics (.ahap) or Meta Haptics Studio (.haptic) file as a clip; "
        "the mapping onto the knobs is the clips: settings (docs/clips.md).",
    )
    add_config_arguments(p)
    p.add_argument("file", type=Path, metavar="FILE.ahap|FILE.haptic")
    p.add_argument("--from", dest="source", choices=sorted(IMPORTERS), help="the file's format (default: its suffix)")
    p.add_argument("--name", type=clip_name_argument, help="clip name (default: the file name)")
    p.add_argument("-o", "--output", type=Path, help="write this clip file (or into this folder) instead")
    p.add_argument("--force", action="store_true", help="replace an existing clip file")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser(
        "export",
        help="write a clip as an Apple Core Haptics AHAP or a Meta Haptics Studio .haptic file",
        description="Export a clip for another tool; the inverse of the import mapping (clips: settings, "
        "docs/clips.md), so importing the file back gives the clip within 0.005 of every value.",
    )
    add_config_arguments(p)
    p.add_argument("name", help="clip name, or a clip file path (FILE.yaml)")
    p.add_argument("--format", choices=sorted(EXPORTERS), default="ahap", help="ahap (Apple, default) or haptic (Meta)")
    p.add_argument(
        "-o", "--output", type=Path, help="output file or folder (default: NAME.ahap / NAME.haptic here; - = stdout)"
    )
    p.add_argument("--force", action="store_true", help="replace an existing file")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("schema", help="print the JSON Schema of a clip file (editor completion)")
    p.set_defaults(func=cmd_schema)

    add_from_audio_parser(sub, add_config_arguments)  # from-audio: the Follow tracker offline (cli/_follow.py)
    add_clip_play_parsers(sub)  # play, stop: a running server plays it (cli/_clip_play.py)
