"""``vibsynth studio``: ``vibsynth serve`` and open the studio in the web browser."""

from __future__ import annotations

import argparse

from vibsynth.cli import serve

ORDER = 6

HELP = """\
Run the engine like `vibsynth serve` (same flags) and open the studio, its browser
workspace, in your web browser: live knobs per channel, the target and measured
spectrum, presets, analysis of a recording, status (docs/studio.md).

The studio's address, with its access token, is printed as a line
  studio: http://127.0.0.1:9571/?token=...
(open it yourself when no browser can be started, e.g. over SSH). Ctrl-C stops.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "studio",
        help="run the engine and open the studio (browser workspace) in a web browser",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    serve.add_arguments(p)
    p.set_defaults(func=run, open_browser=True)


def run(args: argparse.Namespace) -> int:
    if args.no_studio:
        from vibsynth.errors import ParameterError

        raise ParameterError("vibsynth studio --no-studio: nothing to open (use vibsynth serve)")
    return serve.run(args)
