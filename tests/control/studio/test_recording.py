"""The studio's recording panel: upload a WAV (a texture of ../shared), its analysis, a preset from it."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

import vibsynth
from tests.control.studio.helpers import http, raw_request, texture_recording
from vibsynth.control.studio.recording import NON_STATIONARY_DB
from vibsynth.control.studio.security import UPLOAD_CAP
from vibsynth.settings.presets import load_preset


def upload(studio, data: bytes, name: str = "texture.wav") -> tuple[int, dict]:
    headers = {"Content-Type": "audio/wav", "X-Filename": name}
    status, _, body = http(studio, "POST", "/api/recording", body=data, headers=headers)
    return status, json.loads(body)


def make_preset(studio, ident: str, body) -> tuple[int, dict]:
    raw = json.dumps(body).encode()
    status, _, data = http(
        studio, "POST", f"/api/recording/{ident}/preset", body=raw, headers={"Content-Type": "application/json"}
    )
    return status, json.loads(data)


@pytest.mark.shared
def test_a_texture_recording_is_analysed_as_vibsynth_analyze_does(studio, hatt_psd, tmp_path, basis, user_dir):
    expected = texture_recording(tmp_path / "brick.wav", hatt_psd, "Brick 1")
    status, result = upload(studio, (tmp_path / "brick.wav").read_bytes(), "Brick%201.wav")
    assert status == 200, result
    reference = vibsynth.analyze(tmp_path / "brick.wav")
    assert result["file"] == "Brick 1.wav"
    assert result["balance"] == round(reference.balance, 4)
    assert result["intensity"] == round(reference.intensity_knob, 4)
    assert result["scores"] == [round(float(s), 4) for s in reference.scores]
    assert result["band_db"] == [round(float(v), 2) for v in reference.band_db]
    assert abs(result["balance"] - expected["balance"]) < 0.15  # the model's own spectrum, no signal involved
    assert result["stationary"] is True and result["non_stationarity_db"] < NON_STATIONARY_DB
    # the model curve is M + t1 V1 at the recording's mean level: its t1 is the recording's
    model = np.asarray(result["model_db"])
    assert basis.scores(model)[0] == pytest.approx(reference.t1, abs=0.01)  # 0.01 dB rounding
    assert np.mean(model) == pytest.approx(np.mean(reference.band_db), abs=0.01)

    status, made = make_preset(studio, result["id"], {"name": "brick-recorded"})
    assert status == 200, made
    preset = load_preset(user_dir / "brick-recorded.yaml")
    assert preset.balance == round(reference.balance, 4)
    assert preset.intensity == round(min(1.0, max(0.0, reference.intensity_knob)), 4)
    assert preset.provenance["recording"] == "Brick 1.wav"
    assert preset.provenance["t1"] == round(reference.t1, 4)
    assert "studio" in preset.provenance["created_by"]
    # the name is taken now: a second preset of it needs overwrite
    status, again = make_preset(studio, result["id"], {"name": "brick-recorded"})
    assert status == 409 and again["exists"]
    assert make_preset(studio, result["id"], {"name": "brick-recorded", "overwrite": True})[0] == 200


def test_a_non_stationary_recording_is_flagged(studio, tmp_path, basis, rng):
    from vibsynth.dsp.synthesis import synthesize
    from vibsynth.formats.recordings import write_wav

    steady = synthesize(basis.mean_db, fs=8000.0, n_samples=24000, level_db=-40.0, rng=rng).signal
    bursts = steady * np.repeat([1.0, 0.1] * 6, 2000)
    write_wav(tmp_path / "bursts.wav", bursts, 8000.0)
    status, result = upload(studio, (tmp_path / "bursts.wav").read_bytes())
    assert status == 200
    assert result["stationary"] is False and result["non_stationarity_db"] > NON_STATIONARY_DB


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (b"", "empty"),
        (b"RIFF\x00\x00\x00\x00WAVEjunk" + bytes(64), "not a readable WAV"),
        (np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8).tobytes(), "not a readable WAV"),
        (
            b"RIFF"
            + struct.pack("<I", 36)
            + b"WAVEfmt "
            + struct.pack("<IHHIIHH", 16, 1, 0, 8000, 0, 0, 16)
            + b"data"
            + struct.pack("<I", 0),
            "0 channels",
        ),
    ],
)
def test_bad_uploads_get_one_line_and_change_nothing(studio, user_dir, data, says):
    status, result = upload(studio, data, "../../etc/passwd")
    assert status == 400
    assert says in result["message"] and "\n" not in result["message"]
    assert "/tmp" not in result["message"]  # the temporary file is not shown
    assert not user_dir.exists()


def test_a_silent_or_short_recording_is_refused_with_the_reason(studio, tmp_path):
    from vibsynth.formats.recordings import write_wav

    write_wav(tmp_path / "short.wav", np.zeros(100), 8000.0)
    status, result = upload(studio, (tmp_path / "short.wav").read_bytes())
    assert status == 400 and "short" in result["message"]


def test_an_upload_larger_than_the_cap_without_a_length_is_cut_off(studio):
    """Chunked transfer (no Content-Length): the server stops reading at the cap."""
    head = (
        f"POST /api/recording HTTP/1.1\r\nHost: 127.0.0.1:{studio.port}\r\n"
        f"Authorization: Bearer {studio.token}\r\nTransfer-Encoding: chunked\r\n\r\n"
    ).encode()
    chunk = b"\x00" * (1 << 20)
    import socket

    with socket.create_connection(("127.0.0.1", studio.port), timeout=30) as sock:
        sock.sendall(head)
        sent = 0
        answer = b""
        try:
            while sent < UPLOAD_CAP + (8 << 20):  # past the cap, without ending the body
                sock.sendall(f"{len(chunk):x}\r\n".encode() + chunk + b"\r\n")
                sent += len(chunk)
        except (BrokenPipeError, ConnectionResetError):
            pass
        sock.settimeout(30)
        try:
            while chunk_in := sock.recv(65536):
                answer += chunk_in
        except (ConnectionResetError, TimeoutError):
            pass
    # a server still reading would wait for the rest of the body and never answer
    assert answer.startswith(b"HTTP/1.1 413"), answer[:200]
    status = json.loads(http(studio, "GET", "/api/status")[2])
    assert status["studio"]["refused"]["too_large"] == 1


def test_make_preset_checks_its_input(studio):
    status, result = make_preset(studio, "0123456789abcdef", {"name": "x"})
    assert status == 404 and "upload the recording again" in result["message"]
    assert raw_request  # (the helper is shared with the security tests)
