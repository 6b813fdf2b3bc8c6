"""The offline progress bar: counting files, and a render whose callback counts another total (its output)."""

from __future__ import annotations

import io

from vibsynth.cli._progress import RenderProgress


def _final(stream: io.StringIO) -> str:
    return [part for part in stream.getvalue().split("\r") if part][-1]


def test_a_folder_counts_files():
    stream = io.StringIO()
    with RenderProgress("follow", 7, 1.0, stream=stream, enabled=True, unit="files") as bar:
        for done in range(1, 8):
            bar(done, 7)
    assert _final(stream).startswith("follow: 100%|") and "7/7 files" in _final(stream)


def test_a_callback_with_another_total_is_scaled_onto_the_input_seconds():
    stream = io.StringIO()
    bar = RenderProgress("render", 44100 * 10, 44100.0, stream=stream, enabled=True)  # 10 s of input
    bar(48000 * 5, 48000 * 10)  # half of the output (at 48 kHz) is written
    assert bar._bar.n == 44100 * 5
    bar(48000 * 10, 48000 * 10)
    bar.close()
    assert "10.0/10.0 s" in _final(stream) and _final(stream).startswith("render: 100%|")
