"""Controller: target state under out-of-order timetags, concurrent setters, the schedule cap."""

from __future__ import annotations

import threading

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


def test_schedule_cap_is_an_error_and_changes_nothing(bank):
    engine = Engine(bank, channels=1, max_block=256, schedule_capacity=5)
    ctl = Controller(engine)
    for k in range(5):
        ctl.set_knob("intensity", 0.5, at_frame=100_000 + k)
    with pytest.raises(ScheduleFullError, match="schedule_capacity"):
        ctl.set_knob("intensity", 0.7, at_frame=200_000)
    assert ctl.get("intensity") == 0.5
