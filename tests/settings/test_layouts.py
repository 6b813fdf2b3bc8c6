"""Layouts (shipped files a config can name, inline positions) and the ``sources:`` section."""

from __future__ import annotations

import itertools
import json
import math

import pytest

from vibsynth.dsp.spatial import ROLLOFFS
from vibsynth.errors import ConfigError
from vibsynth.settings.config import ENV_VARS, load_config
from vibsynth.settings.layouts import (
    Layout,
    layout_files,
    load_layout,
    read_layout_file,
    resolve_layout,
    user_layout_dir,
)
from vibsynth.settings.models_sources import ROLLOFF_NAMES
from vibsynth.settings.schema import shipped_schema_text
from vibsynth.settings.yamldoc import parse_yaml


@pytest.fixture(autouse=True)
def isolated_dirs(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg-config"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)


def config(tmp_path, text):
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    return path, load_config(path, env={})


# --------------------------------------------------------------------------- shipped layouts
def test_the_shipped_layouts():
    assert set(layout_files()) >= {"glove", "vest-back", "wristband"}
    glove = load_layout("glove")
    assert [p.name for p in glove.channels.values()] == ["thumb", "index", "middle", "ring", "little", "palm"]
    assert glove.channels[6].x == glove.channels[6].y == 0.0  # the palm is the origin


def test_the_vest_is_a_4_by_4_grid_10_cm_apart():
    vest = load_layout("vest-back").channels
    assert sorted(vest) == list(range(1, 17))
    for row, column in itertools.product(range(1, 5), range(1, 5)):
        p = vest[4 * (row - 1) + column]
        assert p.name == f"back-{row}-{column}"
        if column < 4:
            right = vest[4 * (row - 1) + column + 1]
            assert (right.x - p.x, right.z - p.z) == pytest.approx((0.1, 0.0))
        if row < 4:
            below = vest[4 * row + column]
            assert (below.x - p.x, below.z - p.z) == pytest.approx((0.0, -0.1))


def test_the_wristband_is_a_ring_of_8():
    band = load_layout("wristband").channels
    assert sorted(band) == list(range(1, 9))
    radii = [math.hypot(p.x, p.z) for p in band.values()]
    assert radii == pytest.approx([0.028] * 8, abs=1e-4)
    angles = [math.degrees(math.atan2(p.x, p.z)) % 360 for p in band.values()]
    assert angles == pytest.approx([45.0 * k for k in range(8)], abs=0.3)


def test_shipped_layouts_validate_against_the_schema():
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(json.loads(shipped_schema_text("layout")))
    for name, path in layout_files().items():
        data = parse_yaml(open(path).read(), path).data
        validator.validate(json.loads(json.dumps(data)))
        assert read_layout_file(path).name == name
    bad = {"channels": {"1": {"x": 12, "y": 0}}}
    assert not validator.is_valid(bad)


# --------------------------------------------------------------------------- a config names a layout
def test_a_config_names_a_layout(tmp_path):
    _, cfg = config(tmp_path, "audio:\n  channels: 16\nlayout: vest-back\n")
    layout = resolve_layout(cfg.settings.layout)
    assert isinstance(layout, Layout) and layout.name == "vest-back"
    assert layout.channels == tuple(range(16))
    assert layout.coordinates[0] == pytest.approx((-0.15, -0.12, 0.15))
    assert layout.describe() == "layout vest-back (16 actuators)"


def test_an_inline_layout_resolves_too(tmp_path):
    _, cfg = config(tmp_path, "audio:\n  channels: 4\nlayout:\n  3: {x: 0.1, y: 0}\n  1: {x: 0, y: 0, name: a}\n")
    layout = resolve_layout(cfg.settings.layout)
    assert layout.channels == (0, 2) and layout.names == ["a", None]
    assert layout.describe() == "inline layout (2 actuators)"
    _, none = config(tmp_path, "audio:\n  channels: 4\n")
    assert resolve_layout(none.settings.layout) is None


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("audio:\n  channels: 4\nlayout: glove\n", "rig.yaml:3: layout glove places channel 6 but audio.channels = 4"),
        ("audio:\n  channels: 6\nlayout: glov\n", "rig.yaml:3: layout = 'glov': no such layout; did you mean glove?"),
        (
            "layout: ../etc/passwd\n",
            "rig.yaml:1: layout = '../etc/passwd': not an allowed value (allowed: null, a layout name",
        ),
    ],
)
def test_a_bad_layout_name_is_refused_with_file_and_line(tmp_path, text, fragment):
    with pytest.raises(ConfigError) as info:
        config(tmp_path, text)
    assert fragment in str(info.value)


def test_a_user_layout_replaces_a_shipped_one_and_its_errors_name_its_file(tmp_path):
    folder = user_layout_dir()
    folder.mkdir(parents=True)
    (folder / "glove.yaml").write_text("channels:\n  1: {x: 0.01, y: 0.02, name: thumb}\n")
    _, cfg = config(tmp_path, "layout: glove\n")
    assert resolve_layout(cfg.settings.layout).coordinates == [(0.01, 0.02, 0.0)]

    (folder / "glove.yaml").write_text("name: glove\nchannels:\n  1: {x: 0.01, y: 0.02}\n  2: {x: 12, y: 0}\n")
    with pytest.raises(ConfigError) as info:
        config(tmp_path, "audio:\n  channels: 2\nlayout: glove\n")
    assert str(info.value) == f"{folder / 'glove.yaml'}:4: channels.2.x = 12: outside the allowed range [-10, 10] m"

    (folder / "hand.yaml").write_text("name: glove\nchannels:\n  1: {x: 0, y: 0}\n")
    with pytest.raises(ConfigError, match=r"hand.yaml:1: name = 'glove' does not match the file name hand.yaml"):
        load_layout("hand")
    (folder / "empty.yaml").write_text("name: empty\nchannels: {}\n")
    with pytest.raises(ConfigError, match="channels"):
        load_layout("empty")
    with pytest.raises(ConfigError, match="unknown layout 'nope'.*available: empty, glove, hand, vest-back"):
        load_layout("nope")


# --------------------------------------------------------------------------- sources
def test_sources_defaults_and_rolloff_names():
    sources = load_config(env={}, user_file=False).settings.sources
    assert (sources.radius, sources.rolloff, sources.glide_ms, sources.update_ms) == (0.05, "smooth", 20.0, 10.0)
    assert sources.midi == [] and sources.speed is False
    assert ROLLOFF_NAMES == ROLLOFFS  # the settings and the science name the same laws


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("sources:\n  radius: 0\n", "sources.radius = 0: outside the allowed range (0, 10] m"),
        ("sources:\n  radius: 1.0e+30\n", "outside the allowed range (0, 10] m"),
        ("sources:\n  rolloff: cubic\n", "one of linear, smooth, inverse-square, phantom"),
        ("sources:\n  update_ms: 1\n", "sources.update_ms = 1: outside the allowed range [2, 100] ms"),
        (
            "sources:\n  midi:\n    - {source: 1, x: {cc: 20}, y: {cc: 20}}\n",
            "sources.midi[0].y = {'cc': 20}: item 0: cc 20 moves source 1 x already",
        ),
        ("sources:\n  midi:\n    - {source: 17, x: {cc: 20}}\n", "sources.midi[0].source = 17: outside the allowed"),
        ("sources:\n  midi:\n    - {source: 1, x: {cc: 123}}\n", "sources.midi[0].x.cc = 123: outside the allowed"),
        ("sources:\n  midi:\n    - {source: 1}\n", "item 0: binds no coordinate (give x, y or z)"),
        ("sources:\n  midi:\n    - {source: 1, y: {cc: 6}}\n", "item 0: y.cc 6 is reserved for NRPN/RPN data"),
        (
            "sources:\n  midi:\n    - {source: 1, x: {cc: 20, range: [0.1, 0.1]}}\n",
            "item 0: x.range [0.1, 0.1] must span some distance",
        ),
    ],
)
def test_bad_sources_settings_name_file_line_key_and_range(tmp_path, text, fragment):
    with pytest.raises(ConfigError) as info:
        config(tmp_path, text)
    assert str(info.value).startswith(f"{tmp_path / 'rig.yaml'}:"), str(info.value)
    assert fragment in str(info.value)


def test_a_source_controller_must_not_move_a_knob_too(tmp_path):
    with pytest.raises(ConfigError) as info:
        config(tmp_path, "sources:\n  midi:\n    - {source: 2, x: {cc: 74}}\n")
    assert "sources.midi[0].x: cc 74 is bound to midi.mapping.balance too" in str(info.value)
    # on another MIDI channel than the knob's binding it is free
    _, cfg = config(
        tmp_path,
        "midi:\n  mapping:\n    balance: [{cc: 74, channel: 1}]\nsources:\n  midi:\n"
        "    - {source: 2, x: {cc: 74, channel: 2}}\n",
    )
    assert cfg.settings.sources.midi[0].x.cc == 74


# --------------------------------------------------------------------------- per-channel actuator profiles
def write_profile(name, *, absolute=True, rate=48000, gain=0.0):
    from vibsynth.settings.actuators import user_profile_dir

    folder = user_profile_dir()
    folder.mkdir(parents=True, exist_ok=True)
    rate_line = f"rate: {rate}\n" if rate else ""
    (folder / f"{name}.yaml").write_text(
        f"name: {name}\nabsolute: {str(absolute).lower()}\n{rate_line}response: [[10, {gain - 20}], [100, {gain}], "
        f"[1000, {gain}]]\n"
    )


def test_channel_profiles_from_a_pattern_a_list_or_the_layout(tmp_path):
    from vibsynth.settings.layouts import channel_profile_names

    for k in (1, 2, 3):
        write_profile(f"vest-ch{k}", gain=3.0 * k)
    _, cfg = config(tmp_path, "audio:\n  channels: 3\nactuator:\n  channel_profiles: vest-ch{n}\n")
    assert channel_profile_names(cfg.settings) == ["vest-ch1", "vest-ch2", "vest-ch3"]
    text = "audio:\n  channels: 3\nactuator:\n  profile: vest-ch1\n  channel_profiles: [vest-ch2, null]\n"
    _, cfg = config(tmp_path, text)
    assert channel_profile_names(cfg.settings) == ["vest-ch2", None, None]
    text = (
        "audio:\n  channels: 3\nactuator:\n  profile: vest-ch1\nlayout:\n  1: {x: 0, y: 0, profile: vest-ch3}\n"
        "  3: {x: 1, y: 0}\n"
    )
    _, cfg = config(tmp_path, text)
    assert channel_profile_names(cfg.settings) == ["vest-ch3", None, None]
    assert resolve_layout(cfg.settings.layout).profiles == ["vest-ch3", None]
    _, cfg = config(tmp_path, "audio:\n  channels: 2\n")
    assert channel_profile_names(cfg.settings) == [None, None]


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("actuator:\n  channel_profiles: vest\n", "needs {n} once"),
        ("actuator:\n  channel_profiles: vest-{n}-{n}\n", "needs {n} once"),
        ("actuator:\n  channel_profiles: [ok, 'bad name']\n", "channel 2: 'bad name' is not a profile name"),
        ("actuator:\n  channel_profiles: 7\n", "must be a name pattern like vest-ch{n}"),
        ("actuator:\n  channel_profiles: [a, b, c]\n", "lists 3 channels but audio.channels = 2"),
        ("actuator:\n  channel_profiles: nope-ch{n}\n", "channel 1's profile 'nope-ch1' does not exist (allowed: flat"),
        ("layout:\n  1: {x: 0, y: 0, profile: 'a b'}\n", "layout.1.profile"),
        ("layout:\n  1: {x: 0, y: 0, profile: nope}\n", "layout: channel 1's profile 'nope' does not exist"),
    ],
)
def test_bad_channel_profiles_name_the_key_and_the_allowed_values(tmp_path, text, fragment):
    with pytest.raises(ConfigError) as err:
        config(tmp_path, "audio:\n  channels: 2\n" + text)
    assert fragment in str(err.value) and "rig.yaml" in str(err.value)


def test_measured_and_relative_profiles_are_not_mixed(tmp_path):
    write_profile("coil", absolute=True)
    write_profile("shape", absolute=False, rate=None)
    with pytest.raises(ConfigError) as err:
        config(tmp_path, "audio:\n  channels: 2\nactuator:\n  channel_profiles: [coil, shape]\n")
    assert "channels 1 (coil) have measured (absolute) profiles but channels 2 (shape) relative ones" in str(err.value)
    # a channel left to actuator.profile (flat, relative) counts too
    with pytest.raises(ConfigError, match=r"channels 2 \(flat\) relative"):
        config(tmp_path, "audio:\n  channels: 2\nactuator:\n  channel_profiles: [coil]\n")
    _, cfg = config(tmp_path, "audio:\n  channels: 2\nactuator:\n  profile: coil\n  channel_profiles: [coil]\n")
    assert cfg.settings.actuator.channel_profiles == ["coil"]


def test_a_channel_profile_measured_at_another_rate_is_refused(tmp_path):
    write_profile("fast", rate=44100)
    with pytest.raises(ConfigError) as err:
        config(tmp_path, "audio:\n  channels: 2\nactuator:\n  channel_profiles: [null, fast]\n")
    message = str(err.value)
    assert "channel 2: actuator profile 'fast' was measured at 44100 Hz but audio.rate is 48000 Hz" in message
