"""Reading recordings and PSD tables, writing WAV and basis files."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.errors import InputError
from vibsynth.formats.basis_file import load_basis, save_basis
from vibsynth.formats.psd import read_psd_table
from vibsynth.formats.recordings import read_recording, write_wav


@pytest.mark.parametrize("dtype, scale", [(np.int16, 32768), (np.int32, 2**31), (np.float32, 1.0)])
def test_wav_formats_are_scaled_to_unit_full_scale(tmp_path, dtype, scale):
    data = np.array([0, scale // 2 if scale > 1 else 0.5, -(scale // 4 if scale > 1 else 0.25)], dtype=dtype)
    wavfile.write(tmp_path / "a.wav", 8000, data)
    rec = read_recording(tmp_path / "a.wav")
    assert rec.fs == 8000 and np.allclose(rec.samples, [0, 0.5, -0.25])


def test_multichannel_wav_channel_choice(tmp_path):
    wavfile.write(tmp_path / "s.wav", 8000, np.array([[0.1, 0.2], [0.3, 0.4]], dtype=np.float32))
    assert np.allclose(read_recording(tmp_path / "s.wav", channel=1).samples, [0.2, 0.4])
    with pytest.raises(InputError, match=r"has 2 channels; channel 3 \(index 2\) does not exist"):
        read_recording(tmp_path / "s.wav", channel=2)


def _raw_wav(bits: int, data: bytes, *, channels: int = 1, fs: int = 8000, block_align: int | None = None) -> bytes:
    """A PCM WAV file with exactly the header fields given (for files other programs write)."""
    import struct

    container = (bits + 7) // 8
    align = block_align if block_align is not None else container * channels
    fmt = struct.pack("<HHIIHH", 1, channels, fs, fs * align, align, bits)
    body = b"WAVEfmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(data)) + data
    return b"RIFF" + struct.pack("<I", len(body)) + body


@pytest.mark.parametrize(
    "bits, low, high, block_align",
    [
        (8, 0, 255, None),  # full-scale 8-bit
        (7, 0, 254, None),  # 7 bits, left-justified in the 8-bit container as WAV defines
        (16, 0, 255, 1),  # a header that claims 16 bits in 1-byte frames: the container is still unsigned
    ],
)
def test_8_bit_wav_is_unsigned_centred_at_128(tmp_path, bits, low, high, block_align):
    square = np.where(np.arange(800) % 80 < 40, high, low).astype(np.uint8)
    path = tmp_path / "square.wav"
    path.write_bytes(_raw_wav(bits, square.tobytes(), block_align=block_align))
    x = read_recording(path).samples
    assert x.min() == -1.0 and x.max() == (high - 128) / 128  # [0, 255] -> [-1, 127/128]
    assert np.count_nonzero(x == -1.0) == 400 and abs(x.mean() - (high - 128 - 128) / 256) < 1e-12
    # the same square as int16 (the reference scaling) reads the same within one 8-bit step
    ref = np.where(square == high, (high - 128) * 256, -32768).astype(np.int16)
    wavfile.write(tmp_path / "ref.wav", 8000, ref)
    np.testing.assert_allclose(x, read_recording(tmp_path / "ref.wav").samples, atol=1e-12)


def test_zero_channel_and_zero_frame_size_wav_are_one_clear_error(tmp_path):
    (tmp_path / "c0.wav").write_bytes(_raw_wav(16, b"\x00\x01" * 100, channels=0))
    with pytest.raises(InputError, match=r"c0.wav: not a readable WAV file \(its header says 0 channels\)"):
        read_recording(tmp_path / "c0.wav")
    (tmp_path / "a0.wav").write_bytes(_raw_wav(16, b"\x00\x01" * 100, channels=2, block_align=0))
    with pytest.raises(InputError, match="a0.wav: not a readable WAV file .*0 bytes per frame for 2 channels"):
        read_recording(tmp_path / "a0.wav")


def test_text_recording_with_header_and_comments(tmp_path):
    (tmp_path / "r.txt").write_text("# accelerometer\nvalue\n1.0\n-2.5\n3\n")
    rec = read_recording(tmp_path / "r.txt", fs=2800.0)
    assert np.allclose(rec.samples, [1.0, -2.5, 3.0]) and rec.fs == 2800.0
    (tmp_path / "bad.txt").write_text("1.0\nabc\n")
    with pytest.raises(InputError, match="bad.txt:2: not a number"):
        read_recording(tmp_path / "bad.txt", fs=2800.0)


def test_write_wav_pcm16_and_float(tmp_path, rng):
    x = rng.uniform(-0.9, 0.9, 100)
    write_wav(tmp_path / "f.wav", x, 8000.0)
    write_wav(tmp_path / "i.wav", x, 8000.0, sample_format="pcm16")
    assert np.allclose(read_recording(tmp_path / "f.wav").samples, x, atol=1e-7)
    assert np.allclose(read_recording(tmp_path / "i.wav").samples, x, atol=1 / 32768)
    assert not list(tmp_path.glob(".*.tmp"))  # atomic write leaves no temp file


def test_psd_table_errors(tmp_path):
    good = "texture,speed,10,20,40\nA,1,1e-3,2e-3,3e-3\n"
    with gzip.open(tmp_path / "t.csv.gz", "wt") as fh:
        fh.write(good)
    table = read_psd_table(tmp_path / "t.csv.gz")
    assert table.labels == ["A"] and table.psd.shape == (1, 3) and table.meta == [{"speed": "1"}]
    (tmp_path / "ragged.csv").write_text("texture,10,20\nA,1e-3\n")
    with pytest.raises(InputError, match="ragged.csv:2"):
        read_psd_table(tmp_path / "ragged.csv")
    (tmp_path / "neg.csv").write_text("texture,10,20\nA,1e-3,-1\n")
    with pytest.raises(InputError, match="positive"):
        read_psd_table(tmp_path / "neg.csv")


def test_basis_yaml_round_trip_and_errors(tmp_path, basis):
    save_basis(basis, tmp_path / "b.yaml")
    assert load_basis(tmp_path / "b.yaml").id == basis.id
    (tmp_path / "broken.yaml").write_text("mean_db: [1, 2\n")
    with pytest.raises(InputError, match=r"broken.yaml:2:1: YAML syntax error"):
        load_basis(tmp_path / "broken.yaml")
    (tmp_path / "partial.yaml").write_text("mean_db: [1, 2]\n")
    with pytest.raises(InputError, match="partial.yaml: basis is missing the key"):
        load_basis(tmp_path / "partial.yaml")


# --------------------------------------------------------------------------- the one YAML loader (issue 12)
#: The issue's "billion laughs": 9 levels of 9 aliases each, 9**9 = 387 million strings once expanded.
BOMB = (
    "\n".join(
        ["a: &a [x,x,x,x,x,x,x,x,x]"]
        + [f"{b}: &{b} [" + ",".join([f"*{a}"] * 9) + "]" for a, b in zip("abcdefgh", "bcdefghi")]
    )
    + "\n"
)
#: The same shape written out without aliases: the cost of reading an ordinary file this size.
PLAIN = "\n".join(["a: [x,x,x,x,x,x,x,x,x]"] + [f"{b}: [" + ",".join(["xy"] * 9) + "]" for b in "bcdefghi"]) + "\n"


def measure(fn) -> tuple[float, int, BaseException | None]:
    """(seconds, tracemalloc peak bytes, exception raised) of one call."""
    import time
    import tracemalloc

    tracemalloc.start()
    started = time.perf_counter()
    caught = None
    try:
        fn()
    except BaseException as exc:  # noqa: BLE001 - returned to the test
        caught = exc
    seconds = time.perf_counter() - started
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return seconds, peak, caught


def test_bomb_is_refused_fast_with_bounded_memory(tmp_path):
    from vibsynth.formats.yamlio import load_yaml

    (tmp_path / "bomb.yaml").write_text(BOMB)
    (tmp_path / "plain.yaml").write_text(PLAIN)
    assert len(BOMB) < 400 and abs(len(PLAIN) - len(BOMB)) < 60
    plain_s, plain_peak, plain_exc = measure(lambda: load_yaml(tmp_path / "plain.yaml"))
    bomb_s, bomb_peak, bomb_exc = measure(lambda: load_yaml(tmp_path / "bomb.yaml"))
    print(
        f"\nbomb refused in {1e3 * bomb_s:.2f} ms, peak {bomb_peak / 1024:.0f} KiB "
        f"(plain file of the same size read in {1e3 * plain_s:.2f} ms, peak {plain_peak / 1024:.0f} KiB)"
    )
    assert plain_exc is None
    assert isinstance(bomb_exc, InputError)
    assert str(bomb_exc).startswith(
        f"{tmp_path / 'bomb.yaml'}:2:8: YAML alias '*a' (anchor '&a' on line 1): aliases are not allowed in a YAML file"
    )
    assert bomb_peak <= 2 * plain_peak  # refused before any expansion: no more than reading a plain file
    assert bomb_s < 0.2


@pytest.mark.parametrize(
    "text, message",
    [
        ("[" * 10_000 + "]" * 10_000, "x.yaml:1:65: nested more than 64 levels deep (not allowed in a YAML file)"),
        (
            "".join(f"{' ' * i}k{i}:\n" for i in range(1_000)),
            "x.yaml:64:64: nested more than 64 levels deep (not allowed in a YAML file)",
        ),
        ("- " * 10_000 + "x\n", "x.yaml:1:129: nested more than 64 levels deep (not allowed in a YAML file)"),
    ],
    ids=["flow lists", "block mappings", "block lists"],
)
def test_deep_nesting_is_a_clear_error_not_a_recursion_error(text, message):
    from vibsynth.formats.yamlio import load_yaml

    seconds, _peak, exc = measure(lambda: load_yaml(text=text, origin="x.yaml"))
    assert isinstance(exc, InputError) and str(exc) == message and seconds < 0.5


def test_nesting_up_to_the_limit_is_fine():
    from vibsynth.formats.files import MAX_YAML_DEPTH
    from vibsynth.formats.yamlio import load_yaml

    data = load_yaml(text="[" * MAX_YAML_DEPTH + "]" * MAX_YAML_DEPTH).data
    for _ in range(MAX_YAML_DEPTH - 1):
        data = data[0]
    assert data == []


def test_file_over_the_cap_is_refused_before_reading(tmp_path, rng):
    from vibsynth.formats.files import MAX_YAML_BYTES
    from vibsynth.formats.yamlio import load_yaml

    path = tmp_path / "big.yaml"
    path.write_bytes(b"# " + rng.integers(97, 123, 2 * 1024 * 1024, dtype=np.uint8).tobytes() + b"\n")
    seconds, peak, exc = measure(lambda: load_yaml(path, what="a preset"))
    assert isinstance(exc, InputError)
    assert str(exc) == f"{path}: 2,097,155 bytes, over the 1 MiB limit for a preset; not read"
    assert peak < MAX_YAML_BYTES // 8  # the 2 MB were never read into memory
    exactly = tmp_path / "exact.yaml"
    exactly.write_bytes(b"#" * (MAX_YAML_BYTES - 5) + b"\nx: 1")
    assert load_yaml(exactly).data == {"x": 1}  # the cap itself is allowed


def test_text_over_the_cap_and_special_values_are_refused():
    from vibsynth.formats.files import MAX_YAML_BYTES
    from vibsynth.formats.yamlio import load_yaml

    with pytest.raises(InputError, match=r"^VAR: 1,048,578 bytes, over the 1 MiB limit for a setting; not read$"):
        load_yaml(text="#" * (MAX_YAML_BYTES + 2), origin="VAR", what="a setting")
    with pytest.raises(InputError, match=r"^x.yaml: cannot read a value: Exceeds the limit \(4300 digits\)"):
        load_yaml(text="n: " + "9" * 5000, origin="x.yaml")
    with pytest.raises(InputError, match=r"^x.yaml:1:4: YAML alias '\*nowhere': aliases are not allowed"):
        load_yaml(text="a: *nowhere\n", origin="x.yaml")
    with pytest.raises(InputError, match="could not determine a constructor"):
        load_yaml(text="a: !!python/object:os.system ls\n", origin="x.yaml")
    assert load_yaml(text="a: &unused 1\nb: 2\n").data == {"a": 1, "b": 2}  # an anchor alone expands nothing


def test_basis_cap_and_alias(tmp_path, basis):
    from vibsynth.formats.files import MAX_BASIS_BYTES

    shipped = Path(__file__).resolve().parents[2] / "vibsynth" / "data" / "default_basis.yaml"
    assert shipped.stat().st_size * 100 < MAX_BASIS_BYTES
    save_basis(basis, tmp_path / "b.yaml")
    assert "&" not in (tmp_path / "b.yaml").read_text() and "*id" not in (tmp_path / "b.yaml").read_text()
    (tmp_path / "bomb.yaml").write_text(BOMB)
    with pytest.raises(InputError, match=r"bomb.yaml:2:8: YAML alias '\*a' .* not allowed in a basis file"):
        load_basis(tmp_path / "bomb.yaml")
    (tmp_path / "huge.yaml").write_bytes(b"#" * (MAX_BASIS_BYTES + 1))
    with pytest.raises(InputError, match="over the 4 MiB limit for a basis file; not read"):
        load_basis(tmp_path / "huge.yaml")


def test_dump_yaml_never_writes_aliases():
    from vibsynth.formats.yamlio import dump_yaml, load_yaml

    shared = [1, 2]
    text = dump_yaml({"a": shared, "b": shared})
    assert "&" not in text and "*" not in text
    assert load_yaml(text=text).data == {"a": [1, 2], "b": [1, 2]}


# --------------------------------------------------------------------------- atomic writes (issue 12)
def test_new_file_mode_follows_the_umask_and_replaced_file_keeps_its_mode(tmp_path):
    import os
    import stat

    from vibsynth.formats.files import atomic_write_bytes, atomic_write_text

    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "a.txt", "one")
        assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o644  # not mkstemp's 0600
        os.umask(0o077)
        atomic_write_bytes(tmp_path / "b.txt", b"two")
        assert stat.S_IMODE((tmp_path / "b.txt").stat().st_mode) == 0o600
        os.chmod(tmp_path / "a.txt", 0o640)
        atomic_write_text(tmp_path / "a.txt", "three")
        assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o640
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").read_text() == "three" and sorted(p.name for p in tmp_path.iterdir()) == [
        "a.txt",
        "b.txt",
    ]


def _every_writer(tmp_path: Path, name: str) -> Path:
    """Write one file of kind ``name`` with vibsynth's own writer; returns its path."""
    from vibsynth.formats.basis_file import default_basis

    if name == "wav":
        write_wav(tmp_path / "w.wav", np.zeros(100), 8000.0)
        return tmp_path / "w.wav"
    if name == "wav stream":
        from vibsynth.formats.wav_stream import WavStreamWriter

        with WavStreamWriter(tmp_path / "s.wav", 8000.0, 1) as w:
            w.write(np.zeros(100))
            w.close()
        return tmp_path / "s.wav"
    if name == "basis":
        save_basis(default_basis(), tmp_path / "b.yaml")
        return tmp_path / "b.yaml"
    if name == "preset":
        from vibsynth.settings.presets import Preset, save_preset

        return save_preset(Preset(name="mode-test", intensity=0.5, balance=0.0), tmp_path / "mode-test.yaml")
    if name == "plot":
        pytest.importorskip("matplotlib", reason="plots need matplotlib (vibsynth[research])")
        from vibsynth.research.plots import plot_basis

        return plot_basis(default_basis(), tmp_path / "p.png")
    if name == "vbt":
        from vibsynth.dsp.codec import Quantizer, encode_trajectory
        from vibsynth.dsp.synthesis import synthesize
        from vibsynth.formats.vbt import write_vbt

        basis = default_basis()
        x = synthesize(basis.mean_db, fs=2800.0, n_samples=8400, level_db=-40.0, rng=np.random.default_rng(1)).signal
        traj = encode_trajectory(x, fs=2800.0, basis=basis)
        write_vbt(tmp_path / "t.vbt", traj, Quantizer.fit(traj))
        return tmp_path / "t.vbt"
    raise AssertionError(name)


@pytest.mark.parametrize("name", ["wav", "wav stream", "basis", "preset", "plot", "vbt"])
def test_every_writer_creates_files_by_the_umask(tmp_path, name):
    """Every file vibsynth writes is 0666 minus the umask (0644 usually), never a temporary file's 0600."""
    import os
    import stat

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    old = os.umask(0o022)
    try:
        path = _every_writer(tmp_path / "a", name)
        assert stat.S_IMODE(path.stat().st_mode) == 0o644 and path.stat().st_size > 0
        os.umask(0o027)
        path = _every_writer(tmp_path / "b", name)
        assert stat.S_IMODE(path.stat().st_mode) == 0o640
        os.chmod(path, 0o600)  # a replaced file keeps its mode
        os.umask(0o022)
        assert stat.S_IMODE(_every_writer(tmp_path / "b", name).stat().st_mode) == 0o600
    finally:
        os.umask(old)
    assert not [p for p in tmp_path.rglob(".*") if p.name.endswith(".tmp")]


def test_check_writable_and_check_target_refuse_a_read_only_folder(tmp_path):
    from tests.formats.readonly import read_only_folder
    from vibsynth.formats.files import check_writable
    from vibsynth.formats.wav_stream import check_target

    check_writable(tmp_path)
    assert check_target(tmp_path / "x.wav", writable=True) == tmp_path / "x.wav"
    assert list(tmp_path.iterdir()) == []  # the probe left nothing
    with read_only_folder(tmp_path / "ro") as ro:
        check_target(ro / "x.wav")  # without writable=True only the folder's existence is checked
        with pytest.raises(OSError) as info:
            check_target(ro / "x.wav", writable=True)
        assert info.value.filename == str(ro) and info.value.strerror
        assert list(ro.iterdir()) == []


def test_atomic_write_fsyncs_file_and_folder_and_writes_through_links(tmp_path, monkeypatch):
    import os
    import stat

    import vibsynth.formats.files as vio

    synced: list[str] = []
    real_fsync = os.fsync

    def fsync(fd):
        synced.append("folder" if stat.S_ISDIR(os.fstat(fd).st_mode) else "file")
        real_fsync(fd)

    monkeypatch.setattr(vio.os, "fsync", fsync)
    real = tmp_path / "real" / "config.yaml"
    vio.atomic_write(real, "a: 1\n")  # the folder is created
    assert synced == ["file", "folder"]
    link = tmp_path / "config.yaml"
    link.symlink_to(real)
    assert vio.atomic_write(link, "a: 2\n") == real
    assert link.is_symlink() and real.read_text() == "a: 2\n"


def test_failed_write_leaves_the_old_file_and_no_temp(tmp_path):
    from vibsynth.formats.files import atomic_write

    target = tmp_path / "t.bin"
    atomic_write(target, b"old")

    def writer(handle):
        handle.write(b"partial")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, writer)
    assert target.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["t.bin"]
    (tmp_path / "ro").mkdir()
    (tmp_path / "ro" / "x").write_text("old")
    import errno
    import os

    import vibsynth.formats.files as vio

    def no_space(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    real = vio.os.fsync
    vio.os.fsync = no_space
    try:
        with pytest.raises(OSError) as info:
            atomic_write(tmp_path / "ro" / "x", "new")
    finally:
        vio.os.fsync = real
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / "ro" / "x")
    assert (tmp_path / "ro" / "x").read_text() == "old" and os.listdir(tmp_path / "ro") == ["x"]


_KILL_SCRIPT = r"""
import sys, time
from vibsynth.formats.files import atomic_write
path, mode = sys.argv[1], sys.argv[2]
a, b = open(sys.argv[3], "rb").read(), open(sys.argv[4], "rb").read()

def pausing(handle):          # writes half, says so, then waits to be killed
    handle.write(b[: len(b) // 2])
    handle.flush()
    print("half", flush=True)
    time.sleep(60)
    handle.write(b[len(b) // 2:])

if mode == "pause":
    atomic_write(path, pausing)
else:                         # write b, a, b, a, ... as fast as possible
    print("looping", flush=True)
    k = 0
    while True:
        atomic_write(path, b if k % 2 == 0 else a)
        k += 1
"""


def _writer_process(tmp_path, target, a: bytes, b: bytes, mode: str):
    import subprocess
    import sys

    (tmp_path / "a.bin").write_bytes(a)
    (tmp_path / "b.bin").write_bytes(b)
    root = Path(__file__).resolve().parents[2]
    return subprocess.Popen(
        [sys.executable, "-c", _KILL_SCRIPT, str(target), mode, str(tmp_path / "a.bin"), str(tmp_path / "b.bin")],
        stdout=subprocess.PIPE,
        text=True,
        cwd=root,
        env={**__import__("os").environ, "PYTHONPATH": str(root)},
    )


def test_kill_9_mid_write_leaves_the_old_file_and_the_temp_is_ignored(tmp_path, rng):
    """SIGKILL while the helper is half-way through a preset: the old preset is intact, the
    leftover temporary file is not taken for a preset."""
    import signal

    from vibsynth.settings.library import PresetLibrary
    from vibsynth.settings.presets import Preset, preset_to_yaml

    folder = tmp_path / "presets"
    folder.mkdir()
    target = folder / "wet-stone.yaml"
    old = preset_to_yaml(Preset("wet-stone", 0.25, -0.5)).encode()
    padding = "".join(f"# {rng.integers(0, 10**9)}\n" for _ in range(20_000))
    new = (preset_to_yaml(Preset("wet-stone", 0.75, 0.5)) + padding).encode()
    target.write_bytes(old)
    proc = _writer_process(tmp_path, target, old, new, "pause")
    try:
        assert proc.stdout.readline().strip() == "half"
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert target.read_bytes() == old
    leftovers = [p.name for p in folder.iterdir() if p != target]
    assert len(leftovers) == 1 and leftovers[0].startswith(".wet-stone.yaml.") and leftovers[0].endswith(".tmp")
    assert (folder / leftovers[0]).stat().st_size == len(new) // 2  # it really died half-way
    lib = PresetLibrary(None, folder)
    assert lib.names() == ["wet-stone"] and lib.get("wet-stone").intensity == 0.25 and not lib.errors


def test_kill_9_at_random_moments_never_leaves_a_partial_file(tmp_path, rng):
    import signal
    import time

    target = tmp_path / "big.bin"
    a = rng.integers(0, 256, 4 << 20, dtype=np.uint8).tobytes()
    b = rng.integers(0, 256, 4 << 20, dtype=np.uint8).tobytes()
    target.write_bytes(a)
    outcomes = []
    for delay in rng.uniform(0.05, 0.4, 6):
        proc = _writer_process(tmp_path, target, a, b, "loop")
        try:
            assert proc.stdout.readline().strip() == "looping"
            time.sleep(float(delay))
            proc.send_signal(signal.SIGKILL)
            proc.wait(10)
        finally:
            proc.kill()
        content = target.read_bytes()
        assert content in (a, b), f"partial file: {len(content)} bytes"
        outcomes.append("b" if content == b else "a")
        temps = [p for p in tmp_path.iterdir() if p.name.startswith(".big.bin.")]
        for p in temps:  # what a killed writer leaves: hidden, never the target
            p.unlink()
    print(f"\nkill -9 at 6 random moments while rewriting 4 MiB: the target held {outcomes} (never partial)")
