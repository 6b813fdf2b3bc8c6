"""``vibsynth config show|check|path|schema``: the effective configuration and where each value comes from."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import yaml

from vibsynth.cli._table import Column, emit
from vibsynth.errors import ConfigError, ParameterError
from vibsynth.settings.actuators import resolve_actuator_response
from vibsynth.settings.config import (
    ENV_VARS,
    add_config_arguments,
    check_config_file,
    config_from_args,
    user_config_file,
)

__all__ = ["ORDER", "register"]

ORDER = 80


def _value(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True, width=10_000).strip().removesuffix("\n...").strip()


def cmd_show(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    leaves = config.leaves()
    if args.key:
        leaves = {k: v for k, v in leaves.items() if k == args.key or k.startswith(args.key + ".")}
        if not leaves:
            try:
                config.get(args.key)  # raises with a "did you mean"
            except ConfigError as exc:
                raise ParameterError(str(exc)) from None  # a key typed on the command line
    fmt = "json" if args.json else "yaml" if args.yaml else (args.format or "table")
    if fmt == "json":
        print(
            json.dumps(
                {k: {"value": v, "source": config.sources.get(k, "")} for k, v in leaves.items()}, indent=2, default=str
            )
        )
        return 0
    if fmt == "csv":
        table = [{"key": k, "value": _value(v), "source": config.sources.get(k, "")} for k, v in leaves.items()]
        emit(table, (Column("key", "key"), Column("value", "value"), Column("source", "source")), "csv")
        return 0
    if fmt == "yaml":
        print(yaml.safe_dump(config.data, sort_keys=False, default_flow_style=None), end="")
        return 0
    rows = [(k, _value(v), config.sources.get(k, "")) for k, v in leaves.items()]
    width_key = max(len(r[0]) for r in rows)
    width_val = min(48, max(len(r[1]) for r in rows))
    for key, value, source in rows:
        print(f"{key:<{width_key}}  {value:<{width_val}}  # {source}")
    print(f"\nfiles read (lowest first): {', '.join(config.files)}", file=sys.stderr)
    actuator = config.settings.actuator
    if actuator.profile and actuator.response is None:
        points = resolve_actuator_response(actuator)
        print(f"actuator profile {actuator.profile!r}: {len(points)} response points", file=sys.stderr)
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    for path in args.files:
        check_config_file(path)  # raises ConfigError naming file:line, key, value, allowed
        print(f"{path}: OK")
    return 0


def cmd_path(args: argparse.Namespace) -> int:
    user = user_config_file()
    print(f"user config file: {user}{'' if user.exists() else ' (does not exist)'}")
    print("environment variables: " + ", ".join(f"{var} -> {key}" for var, key in ENV_VARS.items()))
    return 0


def cmd_schema(args: argparse.Namespace) -> int:
    from vibsynth.settings.schema import schema_text

    print(schema_text(args.kind), end="")
    return 0


def register(subparsers: Any) -> None:
    """Add ``vibsynth config ...``."""
    parser = subparsers.add_parser(
        "config",
        help="show the effective configuration or check a config file",
        description="Configuration (docs/config.md). Layers: built-in defaults < user config file "
        "(--config, $VIBSYNTH_CONFIG or the platform folder) < VIBSYNTH_* environment variables < "
        "command line (--set KEY=VALUE).",
    )
    sub = parser.add_subparsers(dest="config_command", metavar="ACTION", required=True)

    p = sub.add_parser("show", help="effective config, each value with its source")
    add_config_arguments(p)
    p.add_argument("key", nargs="?", help="only this key or section (e.g. audio, osc.port)")
    fmt = p.add_mutually_exclusive_group()
    fmt.add_argument(
        "--format",
        choices=("table", "json", "csv", "yaml"),
        default=None,
        help="table (default); json or csv: key, value, source; yaml: the effective config as a file",
    )
    fmt.add_argument("--json", action="store_true", help="same as --format json")
    fmt.add_argument("--yaml", action="store_true", help="same as --format yaml")
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("check", help="validate config files (errors name file, line, key, value, range)")
    p.add_argument("files", nargs="+", type=Path, metavar="FILE")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("path", help="where the user config file is and which environment variables apply")
    p.set_defaults(func=cmd_path)

    p = sub.add_parser(
        "schema",
        help="print the JSON Schema of config files (editor completion and inline errors; docs/config.md)",
    )
    p.add_argument(
        "kind",
        nargs="?",
        choices=("config", "actuator"),
        default="config",
        help="config (default) or actuator (an actuator profile)",
    )
    p.set_defaults(func=cmd_schema)
