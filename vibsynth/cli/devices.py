"""``vibsynth devices``: audio host APIs and output devices (and MIDI inputs)."""

from __future__ import annotations

import argparse
import logging

ORDER = 6

log = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("devices", help="list audio host APIs, output devices and MIDI inputs")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from vibsynth.engine.outputs import list_devices
    from vibsynth.errors import DeviceError

    try:
        apis, devices = list_devices()
    except DeviceError as exc:
        print(f"audio: {exc}")
        apis, devices = [], []
    if apis:
        print("Host APIs:")
        for api in apis:
            default = api["default_output_device"]
            print(f"  {api['index']}: {api['name']}" + (f" (default output: {default})" if default >= 0 else ""))
    print("Output devices:" if devices else "Output devices: none (vibsynth serve will use the null output)")
    for d in devices:
        api_name = apis[d["hostapi"]]["name"] if d["hostapi"] < len(apis) else "?"
        mark = "*" if any(a["default_output_device"] == d["index"] for a in apis) else " "
        print(
            f" {mark}{d['index']:3d}: {d['name']}  [{api_name}, {d['max_output_channels']} out, "
            f"{d['default_samplerate']:g} Hz, low latency {1000 * d['default_low_output_latency']:.1f} ms]"
        )
    from vibsynth.control.midi.adapter import list_inputs

    try:
        inputs = list_inputs()
    except Exception as exc:  # MIDI backend missing or failing: not fatal for a listing
        print(f"MIDI inputs: unavailable ({exc})")
        return 0
    print("MIDI inputs:" if inputs else "MIDI inputs: none")
    for i, name in enumerate(inputs):
        print(f"  {i}: {name}")
    return 0
