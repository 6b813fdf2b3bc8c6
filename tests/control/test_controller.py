"""Controller: target state under out-of-order timetags, concurrent setters, the schedule cap."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from vibsynth.control.controller import Controller
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.errors import ScheduleFullError
from vibsynth.formats.basis_file import default_basis


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=16000.0, loop_seconds=1.0, levels=9, seed=2))


def test_out_of_order_timetags_leave_the_latest_timed_value_as_target(bank):
    engine = Engine(bank, channels=2, glide_s=0.0, max_block=256)
    ctl = Controller(engine)
    rng = np.random.default_rng(4)
    frames = [int(f) for f in rng.permutation(np.arange(1000, 9000, 100))]
    for f in frames:
        ctl.set_knob("intensity", f / 10_000, at_frame=f, channels=[0])
    ctl.set_knob("intensity", 0.05, channels=[0])  # immediate: a later-timed value still waits
    assert ctl.get("intensity", 0) == pytest.approx(8900 / 10_000)
    engine.render(10_000)
    # what the engine ends on is what get() said
    assert engine.knob_values()[0][0] == pytest.approx(ctl.get("intensity", 0))
    ctl.set_knob("intensity", 0.2, channels=[0])  # everything has fired: now it wins
    assert ctl.get("intensity", 0) == 0.2


def test_panic_clears_pending_targets(bank):
    engine = Engine(bank, channels=1, max_block=256)
    ctl = Controller(engine)
    ctl.set_knob("intensity", 0.9, at_frame=50_000)
    ctl.panic()
    assert ctl.get("intensity") == 0.0
    ctl.set_knob("intensity", 0.3)
    assert ctl.get("intensity") == 0.3


def test_concurrent_setters_leave_state_equal_to_the_engine(bank):
    engine = Engine(bank, channels=1, glide_s=0.0, max_block=256)
    ctl = Controller(engine)
    out = np.zeros((64, 1), dtype=np.float32)

    def setter(seed: int) -> None:
        for v in np.random.default_rng(seed).uniform(0, 1, 2000):
            ctl.set_knob("intensity", float(v))

    threads = [threading.Thread(target=setter, args=(s,)) for s in range(3)]
    for t in threads:
        t.start()
    while any(t.is_alive() for t in threads):
        engine.render_into(out)
    for _ in range(10):
        engine.render_into(out)
    assert engine.knob_values()[0][0] == ctl.get("intensity")


class OrderEngine:
    """Records what reaches the engine, in order; yields the GIL inside submit to invite races."""

    channels, fs = 1, 48000.0

    def __init__(self) -> None:
        self.submitted: list[float] = []
        self._guard = threading.Lock()  # the list itself; not the controller's ordering

    def submit(self, command) -> int:
        with self._guard:
            self.submitted.append(command.value)
            seq = len(self.submitted)
        time.sleep(0)  # let another setter run between this submit and the controller's bookkeeping
        return seq

    applied_seq = property(lambda self: len(self.submitted))
    frame_position = property(lambda self: 0)


def test_many_threads_on_one_knob_leave_the_state_at_the_last_submitted_value():
    """Submission and bookkeeping are one step: the recorded target is what the engine got last."""
    engine = OrderEngine()
    ctl = Controller(engine)
    start = threading.Barrier(8)

    def setter(seed: int) -> None:
        values = np.random.default_rng(seed).uniform(0, 1, 400)
        start.wait()
        for v in values:
            ctl.set_knob("intensity", float(v))

    for trial in range(5):
        threads = [threading.Thread(target=setter, args=(100 * trial + s,)) for s in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert len(engine.submitted) == (trial + 1) * 8 * 400
        assert ctl.get("intensity") == engine.submitted[-1]
        start.reset()


def test_a_setter_waits_for_the_one_inside_submit():
    """Deterministic interleaving: while A is inside ``engine.submit``, B cannot overtake it."""
    a_inside, b_done = threading.Event(), threading.Event()

    class SlowFirstSubmit(OrderEngine):
        def submit(self, command) -> int:
            if command.value == 0.25:  # A: hold the submit until B finished (or 2 s passed)
                a_inside.set()
                b_done.wait(2.0)
            return super().submit(command)

    engine = SlowFirstSubmit()
    ctl = Controller(engine)
    a = threading.Thread(target=ctl.set_knob, args=("intensity", 0.25))
    a.start()
    assert a_inside.wait(10.0)
    b = threading.Thread(target=lambda: (ctl.set_knob("intensity", 0.75), b_done.set()))
    b.start()
    a.join(10.0)
    b.join(10.0)
    # a racy controller lets B submit and record 0.75 first, then A records 0.25 over it
    assert engine.submitted == [0.25, 0.75]
    assert ctl.get("intensity") == 0.75


def test_schedule_cap_is_an_error_and_changes_nothing(bank):
    engine = Engine(bank, channels=1, max_block=256, schedule_capacity=5)
    ctl = Controller(engine)
    for k in range(5):
        ctl.set_knob("intensity", 0.5, at_frame=100_000 + k)
    with pytest.raises(ScheduleFullError, match="schedule_capacity"):
        ctl.set_knob("intensity", 0.7, at_frame=200_000)
    assert ctl.get("intensity") == 0.5
