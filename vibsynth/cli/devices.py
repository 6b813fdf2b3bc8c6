"""``vibsynth devices``: audio host APIs and output devices, and MIDI inputs."""

from __future__ import annotations

import argparse
import json
import logging
from typing import Any

from vibsynth.cli._table import Column, add_format_argument, emit, output_format

ORDER = 6

log = logging.getLogger(__name__)

DEVICE_COLUMNS = (
    Column("default", "", lambda v: "*" if v else ""),
    Column("index", "index"),
    Column("name", "device", name=True),
    Column("host_api", "host API", name=True),
    Column("outputs", "outputs"),
    Column("rate", "rate Hz", lambda v: f"{v:g}"),
    Column("latency_ms", "low latency ms", lambda v: f"{v:.1f}"),
)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "devices",
        help="list audio output devices (with their host API) and MIDI inputs",
        description="Output devices for --device (index or name substring; * = the default of its host API) "
        "and MIDI inputs for --midi. --format csv lists the audio devices only; json lists both.",
    )
    add_format_argument(p)
    p.set_defaults(func=run)


def _audio() -> tuple[list[dict[str, Any]], str | None]:
    from vibsynth.engine.outputs import list_devices
    from vibsynth.errors import DeviceError

    try:
        apis, devices = list_devices()
    except DeviceError as exc:
        return [], str(exc)
    rows = []
    for d in devices:
        rows.append(
            {
                "default": any(a["default_output_device"] == d["index"] for a in apis),
                "index": d["index"],
                "name": d["name"],
                "host_api": apis[d["hostapi"]]["name"] if d["hostapi"] < len(apis) else "?",
                "outputs": d["max_output_channels"],
                "rate": float(d["default_samplerate"]),
                "latency_ms": 1000.0 * float(d["default_low_output_latency"]),
            }
        )
    return rows, None


def _midi() -> tuple[list[str], str | None]:
    from vibsynth.control.midi.adapter import list_inputs, port_help

    try:
        return list_inputs(), None
    except Exception as exc:  # noqa: BLE001 - a missing or failing MIDI backend is not fatal for a listing
        return [], f"{exc}. {port_help()}"


def run(args: argparse.Namespace) -> int:
    fmt = output_format(args)
    rows, audio_error = _audio()
    if fmt == "csv":
        emit(rows, DEVICE_COLUMNS, "csv")
        return 0
    inputs, midi_error = _midi()
    if fmt == "json":
        out = {"audio": rows, "audio_error": audio_error, "midi_inputs": inputs, "midi_error": midi_error}
        print(json.dumps(out, indent=2))
        return 0
    if audio_error:
        print(f"audio: {audio_error}")
    if rows:
        print("Output devices (* = default of its host API):")
        emit(rows, DEVICE_COLUMNS, "table")
    else:
        print("Output devices: none (vibsynth serve will use the null output)")
    if midi_error:
        print(f"MIDI inputs: unavailable ({midi_error})")
    else:
        if not inputs:
            from vibsynth.control.midi.adapter import port_help

            print(f"MIDI inputs: none. {port_help()}")
        else:
            print("MIDI inputs:")
        for i, name in enumerate(inputs):
            print(f"  {i}: {name}")
    return 0
