"""`vibsynth serve` starts the studio and prints its URL line; `vibsynth studio` also opens a browser."""

from __future__ import annotations

import re
import socket

import pytest

from vibsynth.cli import main

TOKEN = "test-token-0123456789abcdef"
SERVE = ["serve", "--output", "null", "--osc-port", "0", "--no-midi", "--seconds", "0.3"]


@pytest.fixture(autouse=True)
def isolated(tmp_path, monkeypatch):
    monkeypatch.setenv("VIBSYNTH_CONFIG", str(tmp_path / "none.yaml"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.delenv("VIBSYNTH_STUDIO_TOKEN", raising=False)
    (tmp_path / "none.yaml").write_text("version: 1\n")


def test_serve_prints_one_studio_line_with_the_token(capsys):
    assert main([*SERVE, "--studio-port", "0", "--studio-token", TOKEN]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("studio: ")]
    assert len(lines) == 1
    assert re.fullmatch(rf"studio: http://127\.0\.0\.1:\d+/\?token={TOKEN}", lines[0])
    assert re.search(r"vibsynth: studio on http://127\.0\.0\.1:\d+/", out)


def test_the_token_comes_from_the_environment_or_is_random(capsys, monkeypatch):
    monkeypatch.setenv("VIBSYNTH_STUDIO_TOKEN", TOKEN)
    assert main([*SERVE, "--studio-port", "0"]) == 0
    assert f"?token={TOKEN}" in capsys.readouterr().out
    monkeypatch.delenv("VIBSYNTH_STUDIO_TOKEN")
    tokens = set()
    for _ in range(2):
        assert main([*SERVE, "--studio-port", "0"]) == 0
        tokens.add(re.search(r"\?token=(\S+)", capsys.readouterr().out).group(1))
    assert len(tokens) == 2 and all(len(t) >= 32 for t in tokens)


def test_a_bad_token_in_the_environment_is_one_line(capsys, monkeypatch):
    monkeypatch.setenv("VIBSYNTH_STUDIO_TOKEN", "short")
    assert main([*SERVE, "--studio-port", "0"]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [
        "vibsynth: error: $VIBSYNTH_STUDIO_TOKEN: the studio token must be 16-256 characters among letters, "
        "digits and _ . ~ - (got 5 characters)"
    ]


def test_no_studio(capsys):
    assert main([*SERVE, "--no-studio"]) == 0
    assert "studio" not in capsys.readouterr().out
    assert main([*SERVE, "--set", "studio.enabled=false"]) == 0
    assert "studio" not in capsys.readouterr().out


def test_an_explicit_port_in_use_is_one_line_and_the_default_falls_back(capsys):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main([*SERVE, "--studio-port", str(port)]) == 1
        err = capsys.readouterr().err
        lines = [line for line in err.splitlines() if line.strip()]
        assert lines == [
            f"vibsynth: error: studio: cannot listen on 127.0.0.1:{port}: Address already in use "
            "(set studio.port or --studio-port, or --no-studio)"
        ]
        assert main([*SERVE, "--set", f"studio.port={port}"]) == 0
        captured = capsys.readouterr()
        assert f"(port {port} was in use)" in captured.out  # the banner line says so (and the log warns)
        url = re.search(r"studio: http://127\.0\.0\.1:(\d+)/", captured.out)
        assert url and int(url.group(1)) != port


def test_vibsynth_studio_opens_the_browser(capsys, monkeypatch):
    opened = []
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr("webbrowser.open_new_tab", lambda url: opened.append(url) or True)
    assert main(["studio", *SERVE[1:], "--studio-port", "0", "--studio-token", TOKEN]) == 0
    out = capsys.readouterr().out
    assert "vibsynth: opening the studio in your web browser" in out
    url = re.search(r"^studio: (\S+)$", out, re.M).group(1)
    assert opened == [url]


def test_vibsynth_studio_without_a_display_says_to_open_the_url(capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("webbrowser.open_new_tab", lambda url: pytest.fail("no browser without a display"))
    assert main(["studio", *SERVE[1:], "--studio-port", "0"]) == 0
    assert "no graphical display: open the studio URL above in a browser" in capsys.readouterr().out
