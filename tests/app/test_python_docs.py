"""Every Python example of docs/python.md runs, in order, against a real OSC server.

The server is in-process: an OscServer on a real Controller and Engine (tiny bank, silent
real-time output, the shipped presets), on a free port that replaces the documented 9570.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from vibsynth.control.controller import Controller
from vibsynth.control.osc.server import OscServer
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.engine.outputs import NullOutput
from vibsynth.settings.config import load_config
from vibsynth.settings.library import load_library

DOC = Path(__file__).resolve().parents[2] / "docs" / "python.md"
BLOCKS = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.DOTALL)


@pytest.fixture
def server(basis):
    engine = Engine(build_bank(basis, BankSpec(fs=48000.0, loop_seconds=0.5, levels=9, seed=2)), channels=2)
    library = load_library(load_config(user_file=False, env={}))
    controller = Controller(engine, preset_resolver=library.get)
    output = NullOutput(engine, block_size=128)
    output.start()
    osc = OscServer(controller, port=0)
    osc.start()
    try:
        yield osc
    finally:
        osc.stop()
        output.stop()


@pytest.fixture
def isolated(tmp_path, monkeypatch):
    """No user config, presets or VIBSYNTH_* variables of the machine; files land in tmp_path."""
    import os

    for name in list(os.environ):
        if name.startswith("VIBSYNTH_"):
            monkeypatch.delenv(name)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_page_has_examples_of_every_topic():
    text = "\n".join(BLOCKS)
    for needle in (
        "vibsynth.analyze",
        "vibsynth.synthesize",
        "vibsynth.render",
        "vibsynth.Engine",
        "load_config",
        "vibsynth.Preset",
        "vibsynth.Client",
        ".get(",
        ".status()",
        "client.at(",
        "NoReplyError",
    ):
        assert needle in text, needle


def test_python_examples_run(server, isolated, capsys):
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for number, block in enumerate(BLOCKS, 1):
        code = block.replace("9570", str(server.port))
        exec(compile(code, f"{DOC.name} python block {number}", "exec"), namespace)
    out = capsys.readouterr().out
    assert "0.800000011920929" in out  # get after set, as the page says
    assert "refused: channel 64 out of range" in out
    assert "refused: /vibsynth/balance balance 99 is outside the allowed range" in out
    assert "no reply from 127.0.0.1:9 within 0.2 s" in out
    assert (isolated / "my-silk.yaml").is_file() and (isolated / "texture.wav").is_file()
