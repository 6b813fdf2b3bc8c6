"""Generated from the models: docs tables and JSON Schemas (no drift); the schemas agree with the loaders."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

jsonschema = pytest.importorskip("jsonschema")

from vibsynth.cli import main  # noqa: E402
from vibsynth.errors import ConfigError, PresetError  # noqa: E402
from vibsynth.settings.actuators import read_actuator_profile, shipped_profile_dir  # noqa: E402
from vibsynth.settings.config import ENV_VARS, check_config_file, default_config_data  # noqa: E402
from vibsynth.settings.library import shipped_presets_dir  # noqa: E402
from vibsynth.settings.presets import parse_preset  # noqa: E402
from vibsynth.settings.schema import DIALECT, SCHEMAS, json_schema, shipped_schema_text  # noqa: E402
from vibsynth.settings.validation import model_spec  # noqa: E402
from vibsynth.settings.yamldoc import parse_yaml  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def isolated_dirs(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg-config"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg-data"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)


def generator():
    spec = importlib.util.spec_from_file_location("gen_settings_docs", ROOT / "scripts" / "gen_settings_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def validator(name: str):
    schema = json.loads(shipped_schema_text(name))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def as_json(data):
    """What an editor sees: YAML data as JSON (integer keys become strings)."""
    return json.loads(json.dumps(data))


# --------------------------------------------------------------------------- no drift
def test_docs_tables_and_schema_files_match_the_models():
    stale = generator().stale(ROOT)
    assert not stale, f"out of date: {[str(p) for p in stale]}; run: python scripts/gen_settings_docs.py"


def test_docs_tables_hold_every_key_with_its_range_and_default():
    config_md = (ROOT / "docs" / "config.md").read_text(encoding="utf-8")
    presets_md = (ROOT / "docs" / "presets.md").read_text(encoding="utf-8")
    assert "| `audio.rate` | integer | `48000` | an integer in [2400, 384000] Hz | sample rate |" in config_md
    assert "| `balance` | number | **required** | a number in [-4, 4] (knob units) |" in presets_md
    clips_md = (ROOT / "docs" / "clips.md").read_text(encoding="utf-8")
    for name, model in SCHEMAS.items():
        text = {"preset": presets_md, "clip": clips_md}.get(name, config_md)
        for key in model_spec(model).leaves:
            assert f"| `{key}` |" in text, (name, key)


def test_a_drifted_table_is_found(tmp_path):
    module = generator()
    for rel in module.DOCS:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text((ROOT / rel).read_text(encoding="utf-8"), encoding="utf-8")
    for name in SCHEMAS:
        target = tmp_path / f"vibsynth/data/schema/{name}.schema.json"
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(shipped_schema_text(name), encoding="utf-8")
    assert module.stale(tmp_path) == []
    doc = tmp_path / "docs" / "config.md"
    doc.write_text(doc.read_text().replace("an integer in [2400, 384000] Hz", "an integer in [8000, 96000] Hz"))
    assert module.stale(tmp_path) == [Path("docs/config.md")]


# --------------------------------------------------------------------------- the schemas
@pytest.mark.parametrize("name", sorted(SCHEMAS))
def test_schemas_are_draft_2020_12_with_titles_descriptions_defaults_ranges(name):
    schema = json.loads(shipped_schema_text(name))
    assert schema["$schema"] == DIALECT and schema["title"] and schema["additionalProperties"] is False
    for definition in schema.get("$defs", {}).values():
        if definition.get("type") == "object":
            assert definition["additionalProperties"] is False, definition["title"]
    spec = model_spec(SCHEMAS[name])
    for key, leaf in spec.leaves.items():
        assert leaf.schema.get("description"), key
        assert leaf.schema.get("title") or "$ref" in leaf.schema, key  # a $ref's title is its definition's
        assert leaf.required or "default" in leaf.schema, key
    if name == "config":
        rate = schema["$defs"]["Audio"]["properties"]["rate"]
        assert (rate["minimum"], rate["maximum"], rate["default"], rate["type"]) == (2400, 384000, 48000, "integer")
        assert schema["$defs"]["Midi"]["properties"]["mode"]["enum"] == ["gate", "continuous"]
    if name == "preset":
        assert schema["required"] == ["intensity", "balance"]


def test_shipped_files_validate_against_the_schemas():
    config = validator("config")
    config.validate(as_json(default_config_data()))
    presets = validator("preset")
    files = sorted(shipped_presets_dir().glob("*.yaml"))
    assert len(files) >= 12
    for path in files:
        presets.validate(as_json(parse_yaml(path.read_text(), str(path)).data))
    profiles = validator("actuator")
    for path in sorted(shipped_profile_dir().glob("*.yaml")):
        profiles.validate(as_json(parse_yaml(path.read_text(), str(path)).data))
        read_actuator_profile(path)


BAD_CONFIGS = [
    "audio:\n  rate: 100\n",
    "audio:\n  backend: jack\n",
    "audio:\n  channelz: 2\n",
    "audio:\n  latency: 5\n",
    "knobs:\n  glide_ms: true\n",
    "osc:\n  port: 70000\n",
    "osc:\n  allow: '10.0.0.0/8'\n",
    "midi:\n  mode: toggle\n",
    "midi:\n  channel_map: {17: all}\n",
    "midi:\n  mapping:\n    intensity: [{cc: 200}]\n",
    "midi:\n  mapping:\n    balance: [{channel: 3}]\n",
    "midi:\n  nrpn: {pitch: [1, 0]}\n",
    "actuator:\n  response: [[0, 1]]\n",
    "speed:\n  curve: [[0, 0.5]]\n",
    "layout:\n  1: {x: 0}\n",
    "layout:\n  1: {x: 0, y: 0, name: Big Toe}\n",
    "version: 2\n",
]
BAD_PRESETS = [
    "intensity: 1.5\nbalance: 0\n",
    "intensity: true\nbalance: 0\n",
    "intensity: 0.5\n",
    "intensity: 0.5\nbalance: 4.5\n",
    "intensity: 0.5\nbalance: 0\nglide: 20\n",
    "intensity: 0.5\nbalance: 0\nprogram: 128\n",
    "intensity: 0.5\nbalance: 0\ntags: rough\n",
    "intensity: 0.5\nbalance: 0\ntags: ['!bad']\n",
    "intensity: 0.5\nbalance: 0\nprovenance: file.wav\n",
    "version: 9\nintensity: 0.5\nbalance: 0\n",
]


def merged_with_defaults(text: str) -> dict:
    data = default_config_data()
    for key, value in parse_yaml(text, "bad.yaml").data.items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key].update(value)
        else:
            data[key] = value
    return data


@pytest.mark.parametrize("text", BAD_CONFIGS)
def test_bad_configs_are_refused_by_the_schema_and_the_loader(tmp_path, text):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"^{path}:\d+: "):
        check_config_file(path)
    assert not validator("config").is_valid(as_json(parse_yaml(text, "bad.yaml").data)), text
    assert not validator("config").is_valid(as_json(merged_with_defaults(text))), text


@pytest.mark.parametrize("text", BAD_PRESETS)
def test_bad_presets_are_refused_by_the_schema_and_the_loader(text):
    with pytest.raises(PresetError, match=r"^x\.yaml(:\d+)?: "):
        parse_preset(text, "x.yaml", name="x")
    assert not validator("preset").is_valid(as_json(parse_yaml(text, "x.yaml").data)), text


def test_bad_actuator_profile_is_refused_by_the_schema_and_the_loader(tmp_path):
    path = tmp_path / "coil.yaml"
    for text in ("name: coil\nresponse: [[50, 3], [40, 0]]\n", "response: [[40, 0]]\ngain: 3\n", "name: coil\n"):
        path.write_text(text)
        with pytest.raises(ConfigError, match=rf"^{path}(:\d+)?: "):
            read_actuator_profile(path)
        if "[[50, 3], [40, 0]]" not in text:  # strictly increasing points: the loader's rule only
            assert not validator("actuator").is_valid(as_json(parse_yaml(text, "coil.yaml").data)), text


# --------------------------------------------------------------------------- the commands
@pytest.mark.parametrize(
    "argv, name",
    [
        (["config", "schema"], "config"),
        (["preset", "schema"], "preset"),
        (["config", "schema", "actuator"], "actuator"),
    ],
)
def test_schema_commands_print_the_shipped_schema(capsys, argv, name):
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out == shipped_schema_text(name)
    assert json.loads(out) == json_schema(SCHEMAS[name])
