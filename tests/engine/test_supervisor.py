"""Device loss: detection, retry with back-off, re-scan, abandoned hung calls, bounded exit.

A fake sounddevice module stands in for PortAudio. Like the real one, it only sees
devices at ``Pa_Initialize`` (so a restarted JACK server needs a re-scan), and its
streams can die (JACK: inactive, no finished callback; ALSA: finished callback), or
hang in open / terminate. Time is driven explicitly: the supervisor runs on a fake
clock and ``supervisor.step()`` is called by the tests (``restart=False``). Where a real
thread must be waited for (an abandoned call, the supervisor thread), the tests wait on a
condition with a generous deadline, never for a fixed time, and assert no durations.
"""

from __future__ import annotations

import logging
import threading
import types

import numpy as np
import pytest

from vibsynth.engine import outputs
from vibsynth.engine.engine import Engine
from vibsynth.engine.outputs import SoundDeviceOutput
from vibsynth.engine.pa_runtime import PortAudioRuntime
from vibsynth.engine.supervisor import (
    LOST,
    RECOVERING,
    STARTING,
    STOPPED,
    STREAMING,
    Backoff,
    ExitGuard,
    HungCallError,
    StreamSupervisor,
    call_with_timeout,
    hung_calls,
)
from vibsynth.errors import DeviceError

from .waiting import returns, wait_until

JACK_API = {"name": "JACK Audio Connection Kit", "default_output_device": 1}
ALSA_API = {"name": "ALSA", "default_output_device": 0}
ALSA_DEV = {"name": "USB haptics", "hostapi": 0, "max_output_channels": 2}
JACK_DEV = {"name": "system", "hostapi": 1, "max_output_channels": 2}


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> float:
        self.t += dt
        return self.t


class World:
    """What the fake PortAudio would find if it scanned now (JACK server up or down)."""

    def __init__(self, jack_up: bool = True) -> None:
        self.jack_up = jack_up
        self.hang = threading.Event()  # set() releases every hung call
        self.hanging_open = threading.Event()  # set while an open is hung
        self.hang_open = False
        self.hang_terminate = False
        self.open_error: str | None = None

    def scan(self) -> tuple[list[dict], list[dict]]:
        if self.jack_up:
            return [ALSA_API, JACK_API], [ALSA_DEV, JACK_DEV]
        return [ALSA_API], [ALSA_DEV]


class FakeLib:
    """A PortAudio library instance: its own device list, taken at Pa_Initialize."""

    loaded = 0

    def __init__(self, world: World) -> None:
        FakeLib.loaded += 1
        self.world = world
        self.apis, self.devices = [], []
        self.initialized = 0
        self.terminated = 0

    def Pa_Initialize(self) -> int:  # noqa: N802 - PortAudio's name
        self.apis, self.devices = self.world.scan()
        self.initialized += 1
        return 0

    def Pa_Terminate(self) -> int:  # noqa: N802
        if self.world.hang_terminate:
            self.world.hang.wait()
        self.terminated += 1
        return 0


class FakeStream:
    def __init__(self, sd: FakeSd, kind="output", *, callback, userdata, finished_callback, **kwargs) -> None:
        if sd.world.hang_open:
            sd.world.hanging_open.set()
            sd.world.hang.wait()
        if sd.world.open_error:
            raise RuntimeError(sd.world.open_error)
        self.sd, self.kwargs = sd, kwargs
        self.lib = sd._lib
        self.finished_callback = finished_callback
        self.active = False
        self.calls: list[str] = []
        sd.streams.append(self)

    def start(self) -> None:
        self.calls.append("start")
        self.active = True

    def stop(self) -> None:
        self.calls.append("stop")
        self.active = False

    def abort(self) -> None:
        self.calls.append("abort")
        self.active = False

    def close(self) -> None:
        self.calls.append("close")

    def jack_server_died(self) -> None:
        """PortAudio's JACK host API: the stream goes inactive, no finished callback."""
        self.active = False

    def device_error(self) -> None:
        """Other host APIs: the stream ends and calls its finished callback."""
        self.active = False
        self.finished_callback()


class FakeSd(types.SimpleNamespace):
    """The parts of python-sounddevice the output and the runtime use."""

    def __init__(self, world: World, libfile: str) -> None:
        super().__init__()
        self.world = world
        self.streams: list[FakeStream] = []
        self._lib = FakeLib(world)
        self._libname = libfile
        self._initialized = 0
        self._ffi = types.SimpleNamespace(cast=lambda ctype, value: value, dlopen=lambda path: FakeLib(world))
        self._lib.Pa_Initialize()
        self._initialized = 1
        self.default = types.SimpleNamespace(device=(-1, 0))

    def _check(self, code: int, msg: str = "") -> int:
        if code < 0:
            raise RuntimeError(f"{msg}: {code}")
        return code

    def _terminate(self) -> None:
        self._check(self._lib.Pa_Terminate())
        self._initialized -= 1

    def query_hostapis(self, i=None):
        return self._lib.apis if i is None else self._lib.apis[i]

    def query_devices(self, i=None):
        return self._lib.devices if i is None else self._lib.devices[i]

    def _StreamBase(self, *args, **kwargs):  # noqa: N802 - sounddevice's name
        return FakeStream(self, *args, **kwargs)


@pytest.fixture
def world():
    w = World()
    yield w
    w.hang.set()  # release abandoned threads


def install_fake_portaudio(world: World, tmp_path, monkeypatch) -> FakeSd:
    """A fake sounddevice over ``world``, standing in for the real one in the output and the input."""
    libfile = tmp_path / "libportaudio.so.2"
    libfile.write_bytes(b"\x7fELF fake")
    fake = FakeSd(world, str(libfile))
    monkeypatch.setattr(outputs, "import_sounddevice", lambda: fake)
    return fake


@pytest.fixture
def sd(world, tmp_path, monkeypatch):
    return install_fake_portaudio(world, tmp_path, monkeypatch)


def make_output(small_bank, host_api, clock, **kw) -> SoundDeviceOutput:
    engine = Engine(small_bank, channels=1, initial_intensity=0.5, initial_balance=0.7)
    return SoundDeviceOutput(engine, host_api=host_api, block_size=64, restart=False, clock=clock, **kw)


def pump(out: SoundDeviceOutput, blocks: int = 3) -> None:
    """What PortAudio does while a stream runs: call the compiled callback (the heartbeat moves)."""
    buf = np.zeros((64, out.device_channels), dtype=np.float32)
    for _ in range(blocks):
        out.engine._core.run_callback(buf, 0)


def run_until(
    out: SoundDeviceOutput, clock: Clock, state: str, *, step: float = 0.05, limit: float = 30.0, beat: bool = False
) -> float:
    """Step the supervisor on the fake clock until ``state``; returns the clock time it took."""
    start = clock()
    while out.supervisor.step() != state:
        if clock() - start > limit:
            raise AssertionError(
                f"still {out.state!r} ({out.state_reason}) after {limit} s; last error {out.supervisor.last_error!r}"
            )
        clock.advance(step)
        if beat and out.state == RECOVERING:
            pump(out)
    return clock() - start


# ---------------------------------------------------------------------- building blocks
def test_backoff_doubles_to_the_maximum_and_resets():
    b = Backoff(0.25, 2.0)
    assert [b.next() for _ in range(6)] == [0.25, 0.5, 1.0, 2.0, 2.0, 2.0]
    b.reset()
    assert b.next() == 0.25
    with pytest.raises(ValueError):
        Backoff(3.0, 2.0)


def test_call_with_timeout_returns_raises_or_abandons():
    assert call_with_timeout(lambda: 42, 1.0, "answer") == 42
    with pytest.raises(ZeroDivisionError):
        call_with_timeout(lambda: 1 / 0, 1.0, "dividing")
    release = threading.Event()
    try:
        # release.wait() would block forever: the call returns only because it is abandoned
        with pytest.raises(HungCallError, match="Pa_Terminate did not return within 0.1 s"):
            returns(lambda: call_with_timeout(release.wait, 0.1, "Pa_Terminate"), "call_with_timeout")
        assert "Pa_Terminate" in hung_calls()
    finally:
        release.set()
    wait_until(lambda: "Pa_Terminate" not in hung_calls(), "the abandoned call leaves the list once it returns")
    assert issubclass(HungCallError, DeviceError)


def test_exit_guard_exits_with_code_0_after_the_deadline_unless_cancelled():
    codes: list[int] = []
    guard = ExitGuard(0.0, exit=codes.append)
    assert not guard.armed and not guard.join(0)
    guard.arm()
    guard.arm()  # idempotent: one countdown
    assert guard.armed and guard.join(20.0)
    assert codes == [0] and guard.fired
    quiet: list[int] = []
    guard = ExitGuard(3600.0, exit=quiet.append)  # cancelled long before its deadline
    guard.arm()
    guard.cancel()
    assert guard.join(20.0)  # the countdown ended early, without exiting
    assert quiet == [] and not guard.fired
    assert ExitGuard(0.0, exit_code=3, exit=codes.append).exit_code == 3


# ---------------------------------------------------------------------- JACK server death
def test_jack_server_death_is_reported_retried_with_backoff_and_recovered(small_bank, sd, world, caplog):
    clock = Clock()
    out = make_output(small_bank, "JACK", clock)
    knobs_before = out.engine.knob_values()
    out.start()
    assert out.state == STARTING
    pump(out)
    assert out.supervisor.step() == STREAMING and out.state_reason == ""
    first = sd.streams[0]

    with caplog.at_level(logging.INFO):
        world.jack_up = False
        first.jack_server_died()
        clock.advance(0.05)
        assert out.supervisor.step() == LOST
        assert out.state_reason == "JACK server shut down"
        assert "audio device lost: JACK server shut down" in caplog.text
        # a dead JACK stream is never called again: abort/close would wait 10 min, then abort the process
        assert first.calls == ["start"]
        assert out._runtime.dirty

        # retries while the server is down: each re-scans; delays 0.25, 0.5, 1, 2, 2 s
        tries = []
        while len(tries) < 5:
            clock.advance(0.01)
            before = out.supervisor.attempts
            out.supervisor.step()
            if out.supervisor.attempts != before:
                tries.append(round(clock() - 1000.0, 2))
        gaps = np.diff([1000.05 - 1000.0] + tries)
        np.testing.assert_allclose(gaps, [0.25, 0.5, 1.0, 2.0, 2.0], atol=0.011)
        assert out.state == LOST and "no host API matches 'JACK'" in out.supervisor.last_error
        assert out._runtime.generation == 1  # one fresh library copy for the loss, not one per retry
        assert "audio device still unavailable" in caplog.text

        # the server comes back: the next retry finds it, reopens, and the first blocks confirm it
        world.jack_up = True
        took = run_until(out, clock, STREAMING, beat=True)
        assert took <= 2.0 + 0.1
    assert out.state_reason == ""
    assert len(sd.streams) == 2 and sd.streams[1].active and sd.streams[1].lib is sd._lib
    assert out.stats.restarts == 1 and out.engine.stats.output_errors == 1
    assert (out.supervisor.losses, out.supervisor.recoveries) == (1, 1)  # one outage, however many retries
    assert out.engine.knob_values() == knobs_before  # same engine, same knobs
    assert "audio device back: streaming again after" in caplog.text
    out.stop()
    assert sd.streams[1].calls == ["start", "stop", "close"]
    assert out.state == STOPPED


def test_no_heartbeat_is_a_loss_and_the_stalled_stream_is_closed(small_bank, sd, world):
    clock = Clock()
    out = make_output(small_bank, "ALSA", clock)
    out.start()
    pump(out)
    out.supervisor.step()
    assert out.state == STREAMING
    clock.advance(0.45)
    assert out.supervisor.step() == STREAMING  # 0.45 s without a block: still fine
    clock.advance(0.1)
    assert out.supervisor.step() == LOST
    assert out.state_reason == "no heartbeat for 0.5 s"
    assert sd.streams[0].calls == ["start", "abort", "close"]  # not JACK: closed, in bounded time
    assert not out._runtime.dirty  # closed cleanly: the same PortAudio can be re-initialised
    run_until(out, clock, STREAMING, beat=True)
    assert out._runtime.generation == 0 and sd._lib.terminated >= 1  # Pa_Terminate + Pa_Initialize
    out.stop()


def test_stream_finished_by_portaudio_is_a_loss(small_bank, sd, world):
    clock = Clock()
    out = make_output(small_bank, "ALSA", clock)
    out.start()
    pump(out)
    out.supervisor.step()
    sd.streams[0].device_error()
    clock.advance(0.05)
    assert out.supervisor.step() == LOST and out.state_reason == "stream stopped"
    run_until(out, clock, STREAMING, beat=True)
    out.stop()


def test_a_reopened_stream_that_never_beats_is_dropped_and_retried(small_bank, sd, world):
    clock = Clock()
    out = make_output(small_bank, "ALSA", clock)
    out.start()
    pump(out)
    out.supervisor.step()
    sd.streams[0].device_error()
    clock.advance(0.05)
    out.supervisor.step()
    run_until(out, clock, RECOVERING)  # no pumping: the new stream is silent
    run_until(out, clock, LOST)
    assert out.state_reason == "stream stopped"  # the outage's cause is kept
    assert "no heartbeat" in out.supervisor.last_error
    assert sd.streams[1].calls == ["start", "abort", "close"]
    run_until(out, clock, STREAMING, beat=True)
    out.stop()


# ---------------------------------------------------------------------- hung PortAudio calls
def test_an_open_that_hangs_forever_is_abandoned(small_bank, sd, world):
    clock = Clock()
    out = make_output(small_bank, "JACK", clock)
    out.start()
    pump(out)
    out.supervisor.step()
    out._runtime.call_timeout_s = 0.2
    world.hang_open = True
    sd.streams[0].jack_server_died()
    clock.advance(0.05)
    out.supervisor.step()
    clock.advance(0.3)
    assert returns(out.supervisor.step, "a retry whose open hangs forever") == LOST
    assert "opening the audio device did not return within 0.2 s" in out.supervisor.last_error
    assert "opening the audio device" in hung_calls()
    assert out._runtime.dirty  # that instance is never used again
    generation = out._runtime.generation
    world.hang_open = False
    run_until(out, clock, STREAMING, beat=True)
    assert out._runtime.generation == generation + 1
    returns(out.stop, "stop with an abandoned open still hanging")
    assert out.state == STOPPED


def test_retries_wait_while_two_portaudio_calls_are_hung(small_bank, sd, world):
    """A frozen driver: hung calls are not piled up (libjack serialises client opens on one mutex)."""
    clock = Clock()
    out = make_output(small_bank, "ALSA", clock)
    out.start()
    pump(out)
    out.supervisor.step()
    out._runtime.call_timeout_s = 0.1
    world.hang_open = True
    sd.streams[0].device_error()
    clock.advance(0.05)
    out.supervisor.step()
    for _ in range(2):  # two attempts, each with an open that hangs
        clock.advance(2.0)
        out.supervisor.step()
    assert out._runtime.hung() == ["opening the audio device"] * 2
    opened = FakeLib.loaded
    clock.advance(2.0)
    out.supervisor.step()
    assert "waiting for 2 hung PortAudio calls to return" in out.supervisor.last_error
    assert FakeLib.loaded == opened  # no new library copy, no new call
    world.hang_open = False
    world.hang.set()  # the driver wakes up: the hung opens return
    wait_until(lambda: not out._runtime.hung(), "the hung opens return")
    run_until(out, clock, STREAMING, beat=True)
    out.stop()


def test_stop_while_a_retry_hangs_returns_in_bounded_time(small_bank, sd, world):
    out = SoundDeviceOutput(
        Engine(small_bank, channels=1),
        host_api="JACK",
        block_size=64,
        heartbeat_timeout_s=0.2,
        backoff=Backoff(0.05, 0.1),
    )
    out.start()  # the real supervisor thread
    world.hang_open = True
    sd.streams[0].jack_server_died()
    assert world.hanging_open.wait(20.0), "no retry reached the open"  # the supervisor is inside it now
    returns(out.stop, "stop while the supervisor thread is inside a hung open")
    assert out.state == STOPPED and not world.hang.is_set()  # it did not wait for the open


def test_shutdown_with_a_hanging_terminate_gives_up_and_disarms_the_exit_hook(sd, world):
    runtime = PortAudioRuntime(sd, call_timeout_s=0.2)
    world.hang_terminate = True
    assert returns(runtime.shutdown, "shutdown with Pa_Terminate hanging forever") is False
    assert sd._initialized == 0  # sounddevice's atexit hook will not call Pa_Terminate again


def test_shutdown_of_a_dirty_instance_never_terminates(sd, world):
    runtime = PortAudioRuntime(sd)
    runtime.mark_dirty("its JACK server died under an open stream")
    assert runtime.shutdown() is False  # the caller ends the process with os._exit
    assert sd._lib.terminated == 0 and sd._initialized == 0


def test_fresh_library_copy_keeps_the_old_one_loaded(sd, world):
    runtime = PortAudioRuntime(sd)
    old = sd._lib
    runtime.mark_dirty("test")
    world.jack_up = False
    runtime.reinitialize()
    assert sd._lib is not old and runtime.generation == 1 and not runtime.dirty
    assert [a["name"] for a in sd.query_hostapis()] == ["ALSA"]
    assert old.terminated == 0  # never called again
    from vibsynth.engine import pa_runtime

    assert old in pa_runtime._KEEP_ALIVE


class PtrLib:
    """A library called with stream pointers, as sounddevice streams are."""

    def __init__(self, abort_code: int) -> None:
        self.abort_code, self.calls = abort_code, []

    def Pa_AbortStream(self, ptr):  # noqa: N802
        self.calls.append(("abort", ptr))
        return self.abort_code

    def Pa_CloseStream(self, ptr):  # noqa: N802
        self.calls.append(("close", ptr))
        return 0


@pytest.mark.parametrize("abort_code, closed", [(0, True), (-9983, True), (-9999, False)])
def test_a_stream_is_closed_through_its_own_library_only_if_it_stopped(sd, world, abort_code, closed):
    runtime = PortAudioRuntime(sd)
    lib = sd._lib = PtrLib(abort_code)
    stream = types.SimpleNamespace(_ptr="stream-1")
    sd._ffi.NULL = None
    assert runtime.close(stream, dead=False) is closed
    if closed:  # paNoError or paStreamIsStopped: closed, instance still usable
        assert lib.calls == [("abort", "stream-1"), ("close", "stream-1")] and stream._ptr is None
        assert not runtime.dirty
    else:  # the stop failed (JACK gone): Pa_CloseStream would assert; the stream is abandoned
        assert lib.calls == [("abort", "stream-1")] and runtime.dirty


# ---------------------------------------------------------------------- what users see
def test_status_line_and_osc_status_say_device_lost_with_the_reason(small_bank, sd, world):
    from vibsynth.app.service import status_line
    from vibsynth.control.controller import Controller

    clock = Clock()
    out = make_output(small_bank, "JACK", clock)
    out.start()
    pump(out)
    out.supervisor.step()
    assert status_line(out.engine, out).startswith("ch1 I=0.50 B=+0.70")
    sd.streams[0].jack_server_died()
    clock.advance(0.05)
    out.supervisor.step()
    line = status_line(out.engine, out)
    assert line.startswith("device lost: JACK server shut down | ch1 I=0.50 B=+0.70")
    try:
        from vibsynth.control.osc.handler import OscHandler
    except ImportError:
        pytest.skip("OSC adapter not installed")
    ctl = Controller(out.engine)
    ctl.output = out
    status = dict(OscHandler(ctl, sync_worker=None).status_pairs())
    assert status["output"] == "device lost" and status["output_reason"] == "JACK server shut down"
    out.stop()


def test_supervisor_step_does_nothing_once_stopped():
    host = types.SimpleNamespace(
        heartbeat=lambda: 0,
        stream_fault=lambda: "gone",
        drop_stream=lambda: None,
        reopen=lambda: "x",
        housekeeping=lambda: None,
    )
    clock = Clock()
    sup = StreamSupervisor(host, clock=clock)
    assert sup.step() == STOPPED
    sup.begin()
    assert sup.step() == LOST and sup.reason == "gone"
    sup.stop()
    clock.advance(10)
    assert sup.step() == STOPPED and sup.attempts == 0
