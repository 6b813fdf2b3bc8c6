"""``vibsynth config show|check|path``."""

from __future__ import annotations

import json

import pytest

from vibsynth.cli import main
from vibsynth.settings.config import ENV_VARS


@pytest.fixture(autouse=True)
def isolated(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_show_every_key_with_its_source(capsys, tmp_path, monkeypatch):
    user = tmp_path / "u.yaml"
    user.write_text("osc:\n  port: 9100\n")
    monkeypatch.setenv("VIBSYNTH_CHANNELS", "2")
    code, out, _ = run(capsys, "config", "show", "--config", str(user), "--set", "audio.rate=44100")
    assert code == 0
    lines = {line.split()[0]: line for line in out.splitlines() if line.strip()}
    assert "9100" in lines["osc.port"] and f"# {user}:2" in lines["osc.port"]
    assert "# env VIBSYNTH_CHANNELS" in lines["audio.channels"]
    assert "44100" in lines["audio.rate"] and "# command line" in lines["audio.rate"]
    assert "# default (vibsynth/data/config/default.yaml:" in lines["knobs.glide_ms"]


def test_show_one_section_as_json(capsys):
    code, out, _ = run(capsys, "config", "show", "osc", "--json")
    data = json.loads(out)
    assert code == 0 and set(data) == {k for k in data if k.startswith("osc.")} and data["osc.port"]["value"] == 9570


def test_show_unknown_key(capsys):
    code, _, err = run(capsys, "config", "show", "osc.portt")
    assert code == 2 and "did you mean osc.port" in err


def test_show_yaml_is_a_valid_config(capsys, tmp_path):
    code, out, _ = run(capsys, "config", "show", "--yaml")
    path = tmp_path / "effective.yaml"
    path.write_text(out)
    assert code == 0
    assert run(capsys, "config", "check", str(path))[0] == 0


def test_check_ok_and_error(capsys, tmp_path):
    good, bad = tmp_path / "good.yaml", tmp_path / "bad.yaml"
    good.write_text("audio:\n  rate: 44100\n")
    bad.write_text("audio:\n  rate: 44100\nknobs:\n  range_db: -3\n")
    code, out, _ = run(capsys, "config", "check", str(good))
    assert code == 0 and f"{good}: OK" in out
    code, _, err = run(capsys, "config", "check", str(bad))
    assert code == 1  # a bad file: a runtime error (2 is for a bad command line)
    assert f"{bad}:4: knobs.range_db = -3: outside the allowed range (0, 120] dB" in err


def test_bad_set_value(capsys):
    code, _, err = run(capsys, "config", "show", "--set", "audio.rate=1")
    assert code == 2 and "command line: audio.rate = 1: outside the allowed range" in err


def test_path(capsys, tmp_path):
    code, out, _ = run(capsys, "config", "path")
    assert code == 0 and str(tmp_path / "cfg" / "vibsynth" / "config.yaml") in out and "VIBSYNTH_OSC_PORT" in out


def test_show_as_csv(capsys):
    import csv
    import io

    code, out, _ = run(capsys, "config", "show", "osc", "--format", "csv", "--set", "osc.port=9600")
    rows = list(csv.DictReader(io.StringIO(out)))
    port = next(r for r in rows if r["key"] == "osc.port")
    assert code == 0 and port == {"key": "osc.port", "value": "9600", "source": "command line"}
    assert all(r["key"].startswith("osc.") for r in rows) and len(rows) > 10
