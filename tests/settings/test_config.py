"""Config: schema errors (file, line, key, value, range), layering precedence, env vars, actuator profiles."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from vibsynth.errors import ConfigError
from vibsynth.settings.actuators import load_actuator_profile, resolve_actuator_response
from vibsynth.settings.config import (
    ENV_VARS,
    check_config_file,
    default_config_data,
    load_config,
    parse_override,
)
from vibsynth.settings.models import VibsynthConfig
from vibsynth.settings.validation import model_spec
from vibsynth.settings.yamldoc import parse_yaml

KEYS = model_spec(VibsynthConfig).leaves

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def isolated_dirs(tmp_path, monkeypatch):
    """No real user config or presets leak into the tests."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg-config"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg-data"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)


def write(tmp_path: Path, text: str, name: str = "user.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def check_error(tmp_path: Path, text: str, *fragments: str) -> str:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        check_config_file(path)
    message = str(info.value)
    for fragment in fragments:
        assert fragment.format(path=path) in message, message
    return message


# --------------------------------------------------------------------------- one source of truth
def test_repo_config_default_is_the_package_file():
    repo_copy = ROOT / "config" / "default.yaml"
    package = ROOT / "vibsynth" / "data" / "config" / "default.yaml"
    assert repo_copy.read_bytes() == package.read_bytes()
    assert repo_copy.resolve() == package.resolve(), "config/default.yaml must be a symlink to the package data"


def test_every_default_key_is_a_model_key_and_every_model_key_has_its_default():
    config = load_config(user_file=False, env={})
    leaves = config.leaves()
    assert set(leaves) == set(KEYS)
    for key, value in leaves.items():
        assert value == KEYS[key].default, key


def test_default_sources_name_the_package_file_and_line():
    config = load_config(user_file=False, env={})
    assert config.sources["audio.rate"].startswith("default (vibsynth/data/config/default.yaml:")
    line = int(config.sources["osc.port"].rsplit(":", 1)[1].rstrip(")"))
    text = (ROOT / "vibsynth/data/config/default.yaml").read_text().splitlines()
    assert text[line - 1].strip().startswith("port:")


# --------------------------------------------------------------------------- error paths
@pytest.mark.parametrize(
    "text, fragments",
    [
        ("audio:\n  rate: 100\n", ["{path}:2:", "audio.rate = 100", "outside the allowed range [2400, 384000]"]),
        ("audio:\n  rate: 44100.5\n", ["{path}:2:", "audio.rate = 44100.5", "must be an integer"]),
        ("audio:\n  rate: fast\n", ["{path}:2:", "audio.rate = 'fast'", "must be an integer"]),
        ("audio:\n  rate: .nan\n", ["{path}:2:", "must be finite"]),
        ("audio:\n  backend: jack\n", ["{path}:2:", "audio.backend = 'jack'", "one of auto, sounddevice, null, wav"]),
        ("audio:\n  latency: medium\n", ["{path}:2:", "audio.latency = 'medium'", "one of low, high"]),
        ("audio:\n  latency: 5\n", ["{path}:2:", "outside the allowed range (0, 2] s"]),
        ("audio:\n  device: -1\n", ["{path}:2:", "audio.device = -1"]),
        (
            "audio:\n  channelz: 2\n",
            ["{path}:2:", "unknown key 'audio.channelz'", "did you mean audio.channels", "allowed in audio:"],
        ),
        ("audioo:\n  rate: 48000\n", ["{path}:2:", "unknown key 'audioo.rate'"]),
        ("\n\nbank:\n  levels: 1\n", ["{path}:4:", "bank.levels = 1", "[2, 1001]"]),
        ("knobs:\n  limiter_ceiling: 0\n", ["{path}:2:", "outside the allowed range (0, 1]"]),
        ("knobs:\n  glide_ms: true\n", ["{path}:2:", "knobs.glide_ms = true", "must be a number"]),
        ("osc:\n  enabled: yes please\n", ["{path}:2:", "osc.enabled", "true or false"]),
        ("osc:\n  port: 70000\n", ["{path}:2:", "osc.port = 70000", "[0, 65535]"]),
        ("osc:\n  prefix: vibsynth\n", ["{path}:2:", "osc.prefix = 'vibsynth'", "an OSC address"]),
        ("osc:\n  allow: [somewhere]\n", ["{path}:2:", "item 0 ('somewhere') is not an IP address"]),
        ("midi:\n  mode: toggle\n", ["{path}:2:", "midi.mode = 'toggle'", "one of gate, continuous"]),
        ("midi:\n  channel_map: {17: all}\n", ["{path}:2:", "key 17 is not a MIDI channel 1..16"]),
        (
            "midi:\n  mapping:\n    intensity: [{cc: 200}]\n",
            ["{path}:3:", "midi.mapping.intensity", "cc 200 is outside [0, 119]"],
        ),
        ("midi:\n  mapping:\n    volume: [{cc: 7}]\n", ["{path}:3:", "unknown key 'midi.mapping.volume'"]),
        ("actuator:\n  response: [[0, 1]]\n", ["{path}:2:", "Hz 0 is outside (0, inf)"]),
        ("actuator:\n  response: [[100, 0], [50, 0]]\n", ["{path}:2:", "does not increase"]),
        ("actuator:\n  response: [[100, 99]]\n", ["{path}:2:", "value 99 is outside [-60, 60]"]),
        ("speed:\n  curve: [[0, 0.5]]\n", ["{path}:2:", "at least 2 points"]),
        ("speed:\n  curve: [[0, 0.5], [10, 1.5]]\n", ["{path}:2:", "value 1.5 is outside [0, 1]"]),
        ("presets:\n  watch: 1\n", ["{path}:2:", "presets.watch = 1", "true or false"]),
        ("version: 2\n", ["{path}:1:", "version = 2", "newer vibsynth"]),
        ("audio: 5\n", ["{path}:1:", "audio must be a mapping of keys, got 5"]),
        ("- a\n- b\n", ["{path}", "must be a mapping"]),
        ("audio:\n  rate: 48000\n  rate: 44100\n", ["{path}:3:", "'audio.rate' appears twice (first on line 2)"]),
        ("audio:\n  rate: [48000\n", ["{path}:3:", "YAML syntax error"]),
    ],
)
def test_schema_errors_name_file_line_key_value_range(tmp_path, text, fragments):
    check_error(tmp_path, text, *fragments)


@pytest.mark.parametrize(
    "text, fragments",
    [
        ("audio:\n  channels: 2\n  channel_map: [1]\n", ["audio.channel_map = [1]", "audio.channels = 2"]),
        ("knobs:\n  balance_min: 1\n", ["knobs.balance_min = 1"]),
        ("bank:\n  balance_max: 2\n", ["must lie within the bank's grid [-3.5, 2]"]),
        ("audio:\n  channels: 2\nmidi:\n  channel_map: {1: [3]}\n", ["targets actuator channel 3"]),
        ("knobs:\n  initial_balance: 3.9\n", ["knobs.initial_balance = 3.9", "outside the live range"]),
        ("midi:\n  channel_map: {1: [2]}\n", ["targets actuator channel 2", "audio.channels = 1"]),
        ("actuator:\n  profile: nosuch\n", ["actuator.profile = 'nosuch'", "flat, hapcoil-example"]),
    ],
)
def test_cross_field_errors_name_the_line_of_the_offending_key(tmp_path, text, fragments):
    message = check_error(tmp_path, text, "{path}:", *fragments)
    assert message.startswith(str(tmp_path / "user.yaml") + ":")


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        check_config_file(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="is a folder"):
        check_config_file(tmp_path)
    bad = tmp_path / "bin.yaml"
    bad.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ConfigError, match="not a UTF-8"):
        check_config_file(bad)


def test_empty_file_and_empty_section_are_fine(tmp_path):
    assert check_config_file(write(tmp_path, "")).get("audio.rate") == 48000
    assert check_config_file(write(tmp_path, "audio:\n")).get("audio.rate") == 48000


def test_valid_user_file_round_trip(tmp_path):
    config = check_config_file(
        write(
            tmp_path,
            "audio:\n  channels: 2\n  channel_map: [3, 4]\n"
            "midi:\n  channel_map: {1: all, 2: [2]}\n"
            "osc:\n  allow: ['10.0.0.0/8', '127.0.0.1']\n",
        )
    )
    assert config.get("audio.channel_map") == [3, 4]
    assert config.get("midi.channel_map") == {1: "all", 2: [2]}


# --------------------------------------------------------------------------- layering
def test_layering_precedence_default_user_env_cli(tmp_path, monkeypatch):
    user = write(tmp_path, "# comment\nosc:\n  port: 9100\n  host: 127.0.0.2\naudio:\n  rate: 44100\n")
    config = load_config(user)
    assert config.get("osc.port") == 9100 and config.sources["osc.port"] == f"{user}:3"
    assert config.get("knobs.glide_ms") == default_config_data()["knobs"]["glide_ms"]
    assert config.sources["knobs.glide_ms"].startswith("default (")

    monkeypatch.setenv("VIBSYNTH_OSC_PORT", "9200")
    config = load_config(user)
    assert config.get("osc.port") == 9200 and config.sources["osc.port"] == "env VIBSYNTH_OSC_PORT"
    assert config.get("osc.host") == "127.0.0.2"  # untouched keys keep the user file's value

    config = load_config(user, overrides={"osc": {"port": 9300}, "audio.rate": 96000})
    assert config.get("osc.port") == 9300 and config.sources["osc.port"] == "command line"
    assert config.get("audio.rate") == 96000 and config.sources["audio.rate"] == "command line"


def test_user_file_from_platform_dir_and_env_var(tmp_path, monkeypatch):
    platform_file = tmp_path / "xdg-config" / "vibsynth" / "config.yaml"
    platform_file.parent.mkdir(parents=True)
    platform_file.write_text("audio:\n  block_size: 256\n")
    assert load_config().get("audio.block_size") == 256
    assert load_config(user_file=False).get("audio.block_size") == 128
    other = write(tmp_path, "audio:\n  block_size: 512\n", "other.yaml")
    monkeypatch.setenv("VIBSYNTH_CONFIG", str(other))
    assert load_config().get("audio.block_size") == 512  # $VIBSYNTH_CONFIG replaces the platform file
    explicit = write(tmp_path, "audio:\n  block_size: 64\n", "explicit.yaml")
    assert load_config(explicit).get("audio.block_size") == 64  # --config wins over both


@pytest.mark.parametrize(
    "var, text, key, expected",
    [
        ("VIBSYNTH_DEVICE", "Scarlett 2i2", "audio.device", "Scarlett 2i2"),
        ("VIBSYNTH_DEVICE", "3", "audio.device", 3),
        ("VIBSYNTH_CHANNELS", "4", "audio.channels", 4),
        ("VIBSYNTH_OUTPUT", "null", "audio.backend", "null"),
        ("VIBSYNTH_OSC_PORT", "0", "osc.port", 0),
        ("VIBSYNTH_PRESETS_DIR", "/tmp/p", "presets.user_dir", "/tmp/p"),
    ],
)
def test_environment_variables(var, text, key, expected):
    config = load_config(env={var: text}, user_file=False)
    assert config.get(key) == expected
    assert config.sources[key] == f"env {var}"


def test_output_env_var_null_means_the_null_backend_not_none():
    assert load_config(env={"VIBSYNTH_OUTPUT": "null"}, user_file=False).get("audio.backend") == "null"


def test_bad_environment_variable_names_the_variable():
    with pytest.raises(ConfigError, match=r"environment variable VIBSYNTH_OSC_PORT: osc.port = 'abc'"):
        load_config(env={"VIBSYNTH_OSC_PORT": "abc"}, user_file=False)
    with pytest.raises(ConfigError, match=r"VIBSYNTH_CHANNELS: audio.channels = 0: outside"):
        load_config(env={"VIBSYNTH_CHANNELS": "0"}, user_file=False)


def test_empty_environment_variable_is_ignored():
    assert load_config(env={"VIBSYNTH_OSC_PORT": ""}, user_file=False).get("osc.port") == 9570


def test_command_line_override_errors():
    with pytest.raises(ConfigError, match=r"command line: audio.rate = 1: outside"):
        load_config(overrides={"audio.rate": 1}, user_file=False, env={})
    with pytest.raises(ConfigError, match=r"command line: unknown key 'osc.portt'"):
        load_config(overrides={"osc.portt": 1}, user_file=False, env={})
    assert parse_override("audio.rate=44100") == ("audio.rate", 44100)
    assert parse_override("audio.device=Scarlett 2i2") == ("audio.device", "Scarlett 2i2")
    with pytest.raises(ConfigError, match="expected KEY=VALUE"):
        parse_override("audio.rate")


def test_config_section_and_get_unknown():
    config = load_config(user_file=False, env={})
    assert config.section("audio")["rate"] == 48000
    with pytest.raises(ConfigError, match="did you mean audio.rate"):
        config.get("audio.rat")
    with pytest.raises(ConfigError, match="unknown config section"):
        config.section("nope")


def test_yaml_lines_are_one_based_and_nested():
    doc = parse_yaml("a:\n  b:\n    - 1\n    - 2\n", "x.yaml")
    assert doc.lines[("a",)] == 1 and doc.lines[("a", "b")] == 2 and doc.lines[("a", "b", "1")] == 4
    assert doc.where(("a", "b", "9")) == "x.yaml:2"


# --------------------------------------------------------------------------- actuator profiles
def test_actuator_profiles_resolve():
    flat = load_config(user_file=False, env={})
    assert all(db == 0.0 for _, db in resolve_actuator_response(flat.settings.actuator))
    coil = load_config(overrides={"actuator.profile": "hapcoil-example"}, user_file=False, env={})
    points = resolve_actuator_response(coil.settings.actuator)
    peak_hz, peak_db = max(points, key=lambda p: p[1])
    assert peak_hz == 65 and peak_db > 6
    profile = load_actuator_profile("hapcoil-example")
    assert profile["example"] is True and "NOT A MEASUREMENT" in Path(profile["file"]).read_text()
    none = load_config(overrides={"actuator.profile": None}, user_file=False, env={})
    assert resolve_actuator_response(none.settings.actuator) == []


def test_explicit_response_wins_over_profile():
    config = load_config(
        overrides={"actuator.profile": "hapcoil-example", "actuator.response": [[100, -3.0]]}, user_file=False, env={}
    )
    assert resolve_actuator_response(config.settings.actuator) == [(100.0, -3.0)]


def test_user_actuator_profile_and_its_errors(tmp_path):
    folder = tmp_path / "xdg-config" / "vibsynth" / "actuators"
    folder.mkdir(parents=True)
    (folder / "mine.yaml").write_text("name: mine\ndescription: measured\nresponse:\n  - [50, 3]\n  - [40, 0]\n")
    config = load_config(overrides={"actuator.profile": "mine"}, user_file=False, env={})
    with pytest.raises(ConfigError, match=r"mine.yaml:3: response = .*does not increase"):
        resolve_actuator_response(config.settings.actuator)
    (folder / "mine.yaml").write_text("name: mine\nresponse: [[40, 0]]\ngain: 3\n")
    with pytest.raises(ConfigError, match=r"mine.yaml:3: unknown key 'gain'"):
        resolve_actuator_response(config.settings.actuator)
    (folder / "mine.yaml").write_text("name: mine\nresponse: [[40, 0], [50, 3]]\n")
    assert resolve_actuator_response(config.settings.actuator) == [(40.0, 0.0), (50.0, 3.0)]


def test_docs_list_every_key_and_env_var():
    text = (ROOT / "docs" / "config.md").read_text(encoding="utf-8")
    missing = [key for key in KEYS if f"`{key}`" not in text] + [var for var in ENV_VARS if f"`{var}`" not in text]
    assert not missing, f"docs/config.md does not document: {missing}"


def test_backend_null_in_yaml_means_the_null_backend(tmp_path):
    assert check_config_file(write(tmp_path, "audio:\n  backend: null\n")).get("audio.backend") == "null"


def test_midi_nrpn_and_range_bindings_are_accepted_and_checked(tmp_path):
    from vibsynth.errors import ConfigError
    from vibsynth.settings.config import load_config

    good = tmp_path / "good.yaml"
    good.write_text(
        "midi:\n  mapping:\n    balance: [{nrpn: [1, 1], range: [-1.0, 1.0]}, {cc: 74}]\n"
        "  nrpn: {intensity: [2, 0], balance: 300}\n  cc_glide_max_ms: 50\n"
    )
    cfg = load_config(good)
    assert cfg.data["midi"]["mapping"]["balance"][0] == {"nrpn": [1, 1], "range": [-1.0, 1.0]}
    for text, needle in [
        ("midi:\n  mapping:\n    balance: [{nrpn: [1, 200]}]\n", "nrpn [1, 200]"),
        ("midi:\n  mapping:\n    balance: [{cc: 1, nrpn: 2}]\n", "either a cc or an nrpn"),
        ("midi:\n  mapping:\n    balance: [{cc: 1, range: [1, 0]}]\n", "low < high"),
        ("midi:\n  nrpn: {pitch: [1, 0]}\n", "unknown knob 'pitch'"),
    ]:
        bad = tmp_path / "bad.yaml"
        bad.write_text(text)
        with pytest.raises(ConfigError, match=re.escape(needle)):
            load_config(bad)


# --------------------------------------------------------------------------- the one YAML loader (issue 12)
BOMB = (
    "\n".join(
        ["a: &a [x,x,x,x,x,x,x,x,x]"]
        + [f"{b}: &{b} [" + ",".join([f"*{a}"] * 9) + "]" for a, b in zip("abcdefgh", "bcdefghi")]
    )
    + "\n"
)


def test_config_bomb_is_refused_fast_naming_file_and_line(tmp_path):
    import time

    path = write(tmp_path, "audio:\n  rate: 48000\n" + BOMB)
    started = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        check_config_file(path)
    assert time.perf_counter() - started < 0.5
    assert str(info.value).startswith(
        f"{path}:4:8: YAML alias '*a' (anchor '&a' on line 3): aliases are not allowed in a config file"
    )


def test_config_merge_key_needs_an_alias_and_is_refused(tmp_path):
    path = write(tmp_path, "base: &base {rate: 44100}\naudio:\n  <<: *base\n")
    with pytest.raises(ConfigError, match=r"user.yaml:3:7: YAML alias '\*base' \(anchor '&base' on line 1\)"):
        check_config_file(path)


def test_oversized_and_deep_config_files(tmp_path):
    big = write(tmp_path, "audio:\n  rate: 48000\n" + "#" * (2 << 20) + "\n", "big.yaml")
    with pytest.raises(
        ConfigError,
        match=r"big.yaml: 2,097,174 bytes, over the 1 MiB limit for a config file; "
        r"not read$",
    ):
        check_config_file(big)
    deep = write(tmp_path, "audio: " + "[" * 10_000 + "]" * 10_000 + "\n", "deep.yaml")
    with pytest.raises(ConfigError, match=r"deep.yaml:1:71: nested more than 64 levels deep"):
        check_config_file(deep)


def test_environment_and_command_line_values_go_through_the_same_loader():
    with pytest.raises(ConfigError, match=r"^environment variable VIBSYNTH_DEVICE:1:12: YAML alias '\*x'"):
        load_config(env={"VIBSYNTH_DEVICE": "[&x [1,2], *x]"}, user_file=False)
    with pytest.raises(ConfigError, match=r"^command line: --set osc.allow:1:16: YAML alias"):
        parse_override("osc.allow=[&x '1.2.3.4', *x]")
    # text that is not YAML stays a plain string, as before
    assert parse_override("audio.device=[Scarlett") == ("audio.device", "[Scarlett")
    assert (
        load_config(env={"VIBSYNTH_DEVICE": "Scarlett: 2i2 [USB"}, user_file=False).get("audio.device")
        == "Scarlett: 2i2 [USB"
    )


def test_long_values_are_shortened_in_messages(tmp_path):
    path = write(tmp_path, "audio:\n  rate: [" + ", ".join(str(k) for k in range(50_000)) + "]\n")
    with pytest.raises(ConfigError) as info:
        check_config_file(path)
    message = str(info.value)
    assert message.startswith(f"{path}:2: audio.rate = [0, 1, 2, 3, 4, 5, 6, 7, ...]: must be an integer")
    assert len(message) < 300 + len(str(path))


def test_actuator_profile_bomb_is_refused(tmp_path):
    folder = tmp_path / "xdg-config" / "vibsynth" / "actuators"
    folder.mkdir(parents=True)
    (folder / "coil.yaml").write_text("name: coil\nresponse: [[40, 0]]\n" + BOMB)
    config = load_config(overrides={"actuator.profile": "coil"}, user_file=False, env={})
    with pytest.raises(ConfigError, match=r"coil.yaml:4:8: YAML alias '\*a' .* not allowed in an actuator profile"):
        resolve_actuator_response(config.settings.actuator)


def test_config_check_and_the_midi_input_agree_on_bindable_controllers(tmp_path):
    """CC 120-127 are channel mode messages: refused by config check, as by the MIDI mapper at serve."""
    from vibsynth.control.midi.bindings import parse_bindings

    for cc, ok in ((119, True), (120, False), (127, False)):
        path = tmp_path / f"cc{cc}.yaml"
        path.write_text(f"midi:\n  mapping:\n    intensity: [{{cc: {cc}}}]\n")
        try:
            check_config_file(path)
            checked = True
        except ConfigError:
            checked = False
        try:
            parse_bindings({"intensity": [{"cc": cc}]})
            parsed = True
        except ConfigError:
            parsed = False
        assert checked == parsed == ok, cc
