"""The typed settings models: one definition of every key; defaults, errors (file:line, key, range), layouts, flags."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from vibsynth.errors import ConfigError, PresetError
from vibsynth.formats.yamlio import dump_yaml
from vibsynth.settings.cli_args import flag_choices, flag_help, flag_type
from vibsynth.settings.config import ENV_VARS, check_config_file, default_config_data, load_config, settings_of
from vibsynth.settings.fields import describe, fmt_number
from vibsynth.settings.models import PresetModel, VibsynthConfig, bounds_of, default_of
from vibsynth.settings.presets import parse_preset
from vibsynth.settings.validation import InvalidConfigError, InvalidPresetError, model_spec

ROOT = Path(__file__).resolve().parents[2]
SPEC = model_spec(VibsynthConfig)


@pytest.fixture(autouse=True)
def isolated_dirs(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg-config"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg-data"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)


def leaf_items(data: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if dotted in SPEC.sections and isinstance(value, dict):
            out.update(leaf_items(value, dotted + "."))
        else:
            out[dotted] = value
    return out


# --------------------------------------------------------------------------- one definition
def test_default_yaml_equals_the_model_defaults_key_by_key():
    """vibsynth/data/config/default.yaml is the annotated copy; neither it nor the models can drift."""
    from_file = leaf_items(default_config_data())
    assert list(from_file) == list(SPEC.leaves), "default.yaml must list every key, in the models' order"
    for key, leaf in SPEC.leaves.items():
        assert from_file[key] == leaf.default, f"{key}: default.yaml has {from_file[key]!r}, the model {leaf.default!r}"
        assert type(from_file[key]) is type(leaf.default), key  # 20.0 stays a float, 1 an int
    dumped = VibsynthConfig().model_dump(mode="json", exclude_none=False)
    assert dumped["knobs"]["glide_ms"] == 20.0 and dumped["audio"]["rate"] == 48000


def test_every_key_has_help_and_a_described_range():
    for spec in (SPEC, model_spec(PresetModel)):
        for key, leaf in spec.leaves.items():
            assert leaf.help and len(leaf.help.splitlines()) == 1, key
            assert describe(leaf.schema, spec.defs), key


def test_typed_settings_beside_the_plain_data(tmp_path):
    path = tmp_path / "u.yaml"
    path.write_text("audio:\n  channels: 2\nosc:\n  port: 9100\nmidi:\n  mapping:\n    balance: [{nrpn: [1, 1]}]\n")
    config = load_config(path, env={})
    settings = config.settings
    assert isinstance(settings, VibsynthConfig)
    assert (settings.audio.channels, settings.osc.port, settings.audio.rate) == (2, 9100, 48000)
    assert settings.midi.mapping.balance[0].nrpn == [1, 1] and settings.midi.mapping.intensity[0].cc == 11
    assert settings.midi.nrpn.intensity == [1, 0]
    assert config.data["osc"]["port"] == 9100 and config.get("audio.channels") == 2  # the old API still works
    assert config.sources["audio.channels"] == f"{path}:2"


def test_settings_of_a_plain_dict_fills_defaults_and_checks():
    assert settings_of({"audio": {"rate": 44100}}).audio.rate == 44100
    assert settings_of(argparse.Namespace(data={})).knobs.glide_ms == 20.0
    with pytest.raises(ConfigError, match=r"^config: osc.port = 70000: outside the allowed range \[0, 65535\]"):
        settings_of({"osc": {"port": 70000}})


def test_defaults_used_elsewhere_come_from_the_models():
    from vibsynth.control.controller import KnobLimits

    limits = KnobLimits()
    assert (limits.balance_min, limits.balance_max) == (
        default_of("knobs.balance_min"),
        default_of("knobs.balance_max"),
    )
    assert limits.glide_max_s * 1000 == bounds_of("knobs.glide_ms")[1]
    assert bounds_of("audio.rate") == (2400, 384000) and bounds_of("osc.reply_port") == (1, 65535)


# --------------------------------------------------------------------------- errors: file, line, key, value, range
BAD_CONFIGS = [
    # (text, line, key, value shown, message fragment)
    ("audio:\n  rate: 100\n", 2, "audio.rate", "100", "outside the allowed range [2400, 384000] Hz"),
    ("audio:\n  rate: 48000.0\n", 2, "audio.rate", "48000.0", "must be an integer"),
    ("\naudio:\n  channels: true\n", 3, "audio.channels", "true", "must be an integer"),
    ("knobs:\n  range_db: 0\n", 2, "knobs.range_db", "0", "outside the allowed range (0, 120] dB"),
    ("knobs:\n  initial_intensity: '0.5'\n", 2, "knobs.initial_intensity", "'0.5'", "must be a number"),
    ("osc:\n  tcp_max_per_peer: 0\n", 2, "osc.tcp_max_per_peer", "0", "outside the allowed range [1, 1024]"),
    ("osc:\n  reply_port: 0\n", 2, "osc.reply_port", "0", "outside the allowed range [1, 65535]"),
    ("osc:\n  host: ''\n", 2, "osc.host", "''", "must be a host name or IP address"),
    ("midi:\n  velocity_curve: 20\n", 2, "midi.velocity_curve", "20", "outside the allowed range [0.1, 10]"),
    ("midi:\n  port: -3\n", 2, "midi.port", "-3", "outside the allowed range [0, inf]"),
    ("midi:\n  attack_ms: .inf\n", 2, "midi.attack_ms", "inf", "must be finite"),
    ("midi:\n  nrpn: {intensity: [1, 200]}\n", 2, "midi.nrpn", "{'intensity': [1, 200]}", "nrpn [1, 200]"),
    ("speed:\n  curve: [[0, 0], [0, 1]]\n", 2, "speed.curve", "[[0, 0], [0, 1]]", "does not increase"),
    ("bank:\n  seed: -1\n", 2, "bank.seed", "-1", "outside the allowed range [0, 4294967295]"),
    ("audio:\n  channel_map: [1, 1]\n", 2, "audio.channel_map", "[1, 1]", "lists a device output twice"),
    ("layout:\n  1: {x: 0, y: 11}\n", 2, "layout.1.y", "11", "outside the allowed range [-10, 10] m"),
    ("layout:\n  1:\n    x: 0\n    y: 0\n    name: Big Toe\n", 5, "layout.1.name", "'Big Toe'", "lower-case"),
]


@pytest.mark.parametrize("text, line, key, shown, fragment", BAD_CONFIGS, ids=[c[2] for c in BAD_CONFIGS])
def test_bad_config_values_name_file_line_key_value_range(tmp_path, text, line, key, shown, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(InvalidConfigError) as info:
        check_config_file(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{line}: {key} = {shown}: "), message
    assert fragment in message and "\n" not in message
    first = info.value.problems[0]
    assert (first.key, first.where, first.line) == (key, f"{path}:{line}", line)
    assert fragment in first.message


def test_every_problem_is_kept_structured_first_in_file_order(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("osc:\n  port: -1\naudio:\n  rate: 1\n  channelz: 2\n")
    with pytest.raises(InvalidConfigError) as info:
        check_config_file(path)
    problems = info.value.problems
    assert [(p.key, p.line) for p in problems] == [("osc.port", 2), ("audio.rate", 4), ("audio.channelz", 5)]
    assert problems[1].value == 1 and "[2400, 384000]" in problems[1].message
    assert str(info.value) == problems[0].text


def test_preset_problems_are_structured_for_forms():
    with pytest.raises(InvalidPresetError) as info:
        parse_preset("intensity: 2\nbalance: -9\nprogram: 1.5\n", "x.yaml", name="x")
    assert [(p.key, p.value, p.line) for p in info.value.problems] == [
        ("intensity", 2, 1),
        ("balance", -9, 2),
        ("program", 1.5, 3),
    ]
    assert info.value.problems[1].message == "outside the allowed range [-4, 4] (knob units)"
    assert isinstance(info.value, PresetError)


# --------------------------------------------------------------------------- property tests (seeded)
def random_value(key: str, rng: np.random.Generator):
    """A random valid value of a numeric or choice key (None for others)."""
    schema = SPEC.leaves[key].schema
    options = [o for o in schema.get("anyOf", [schema]) if o.get("type") != "null"]
    for option in options:
        if "enum" in option:
            return str(rng.choice([v for v in option["enum"] if v is not None]))
        if option.get("type") in ("integer", "number"):
            low = option.get("minimum", option.get("exclusiveMinimum", -1e6))
            high = option.get("maximum", option.get("exclusiveMaximum", 1e6))
            if option["type"] == "integer":
                return int(rng.integers(low, min(high, 10**9) + 1))
            value = float(rng.uniform(low, high))
            return value if value != option.get("exclusiveMinimum") else high
        if option.get("type") == "boolean":
            return bool(rng.random() < 0.5)
    return None


def NUMERIC(key: str) -> bool:
    schema = SPEC.leaves[key].schema
    return any(o.get("type") in ("integer", "number") for o in schema.get("anyOf", [schema]))


SCALARS = [k for k in SPEC.leaves if random_value(k, np.random.default_rng(0)) is not None]
# keys tied to others by the rules between keys are left out of the random configs
TIED = {
    "bank.balance_min",
    "bank.balance_max",
    "knobs.balance_min",
    "knobs.balance_max",
    "knobs.initial_balance",
    "clips.sharpness_0_balance",
    "clips.sharpness_half_balance",
    "clips.sharpness_1_balance",
}
TIED |= {"lab.gain_min", "lab.gain_max"}  # gain_min < gain_max


@pytest.mark.parametrize("seed", range(5))
def test_random_valid_configs_round_trip(seed, tmp_path):
    rng = np.random.default_rng(seed)
    for i in range(10):
        data = default_config_data()
        chosen = {}
        for key in SCALARS:
            if key in TIED or key == "audio.channels" or rng.random() < 0.5:
                continue
            chosen[key] = random_value(key, rng)
            section, name = key.rsplit(".", 1) if "." in key else ("", key)
            (data[section] if section else data)[name] = chosen[key]
        path = tmp_path / f"c{i}.yaml"
        path.write_text(dump_yaml(data, sort_keys=False))
        config = check_config_file(path)
        for key, value in chosen.items():
            assert config.get(key) == value, key
        again = tmp_path / f"again{i}.yaml"
        again.write_text(dump_yaml(config.settings.model_dump(mode="python"), sort_keys=False))
        assert check_config_file(again).settings == config.settings


@pytest.mark.parametrize("seed", range(3))
def test_random_out_of_range_values_name_the_key_and_the_range(seed, tmp_path):
    rng = np.random.default_rng(seed)
    numeric = [k for k in SCALARS if k != "version" and NUMERIC(k) and bounds_of(k) != (None, None)]
    for key in rng.choice(numeric, size=12, replace=False):
        low, high = bounds_of(str(key))
        bad = (high + 1 + float(rng.uniform(0, 100))) if high is not None else (low - 1 - float(rng.uniform(0, 100)))
        schema = SPEC.leaves[str(key)].schema
        options = [o for o in schema.get("anyOf", [schema]) if o.get("type") in ("integer", "number")]
        if options[0]["type"] == "integer":
            bad = math.floor(bad) if high is None else math.ceil(bad)
        section, name = str(key).split(".")
        path = tmp_path / "bad.yaml"
        path.write_text(f"# random\n{section}:\n  {name}: {bad!r}\n")
        with pytest.raises(ConfigError) as info:
            check_config_file(path)
        message = str(info.value)
        assert message.startswith(f"{path}:3: {key} = {bad!r}: outside the allowed range "), message
        bounds = f"{'-inf' if low is None else fmt_number(low)}, {'inf' if high is None else fmt_number(high)}"
        assert bounds in message, message


# --------------------------------------------------------------------------- layout
def test_layout_is_typed_and_checked_against_the_channels(tmp_path):
    path = tmp_path / "rig.yaml"
    path.write_text(
        "audio:\n  channels: 3\nlayout:\n  1: {x: -0.08, y: 0.02, name: thumb}\n"
        "  2: {x: 0.0, y: -0.25, z: 0.3, name: back-3-2}\n"
    )
    layout = check_config_file(path).settings.layout
    assert layout is not None and set(layout) == {1, 2}
    assert (layout[1].x, layout[1].z, layout[1].name, layout[2].z) == (-0.08, 0.0, "thumb", 0.3)

    for text, fragment in [
        ("layout:\n  2: {x: 0, y: 0}\n", "layout: channel 2 is placed but audio.channels = 1"),
        ("layout:\n  0: {x: 0, y: 0}\n", "key 0 is not an output channel 1..64"),
        (
            "audio:\n  channels: 2\nlayout:\n  1: {x: 0, y: 0, name: a}\n  2: {x: 0, y: 1, name: a}\n",
            "layout.2 = {'name': 'a', 'x': 0, 'y': 1}: channel 2: name 'a' is already channel 1's",
        ),
        ("layout:\n  1: {x: 0}\n", "layout.1: missing key 'y'"),
        ("layout:\n  1: {x: 0, y: 0, w: 1}\n", "unknown key 'layout.1.w' (allowed: x, y, z, name, profile)"),
        ("layout: [1, 2]\n", "layout = [1, 2]: must be a layout name or a mapping of positions (allowed: null,"),
    ]:
        path.write_text(text)
        with pytest.raises(ConfigError) as info:
            check_config_file(path)
        assert str(info.value).startswith(f"{path}:"), str(info.value)
        assert fragment in str(info.value), str(info.value)


def test_layout_error_names_the_layout_line_whatever_layer_set_the_channels(tmp_path):
    path = tmp_path / "rig.yaml"
    path.write_text("audio:\n  channels: 2\nlayout:\n  1: {x: 0, y: 0}\n  2: {x: 0, y: 1}\n")
    assert load_config(path, env={}).settings.audio.channels == 2
    with pytest.raises(ConfigError) as info:
        load_config(path, env={"VIBSYNTH_CHANNELS": "1"})
    assert str(info.value).startswith(f"{path}:3: layout: channel 2 is placed but audio.channels = 1")


# --------------------------------------------------------------------------- command-line flags
def test_flag_types_take_their_ranges_from_the_models():
    channels = flag_type("audio.channels")
    assert channels("4") == 4
    with pytest.raises(argparse.ArgumentTypeError, match=r"^0 is outside the allowed range \[1, 64\]$"):
        channels("0")
    with pytest.raises(argparse.ArgumentTypeError, match="must be an integer"):
        channels("two")
    assert flag_type("audio.device")("3") == 3 and flag_type("audio.device")("Scarlett 2i2") == "Scarlett 2i2"
    balance = flag_type("balance", PresetModel)
    assert balance("-0.5") == -0.5
    with pytest.raises(argparse.ArgumentTypeError, match=r"nan is outside the allowed range \[-4, 4\]"):
        balance("nan")
    assert flag_choices("audio.backend") == ("auto", "sounddevice", "null", "wav")
    assert "an integer in [0, 65535]" in flag_help("osc.port") and "9570" in flag_help("osc.port")


def test_serve_flags_are_checked_by_the_models(capsys):
    from vibsynth.cli import build_parser

    parser = build_parser()
    with pytest.raises(SystemExit):
        parser.parse_args(["serve", "--channels", "65"])
    assert "65 is outside the allowed range [1, 64]" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parser.parse_args(["serve", "--osc-port", "70000"])
    assert "70000 is outside the allowed range [0, 65535]" in capsys.readouterr().err
    args = parser.parse_args(["serve", "--device", "2", "--channels", "2", "--output", "null"])
    assert (args.device, args.channels, args.output) == (2, 2, "null")
