"""The input tap: bounded, cursor-read, free when nobody listens; errors always kept."""

from __future__ import annotations

import threading

import numpy as np

from vibsynth.control.tap import ERRORS_KEPT, MAX_TEXT, InputTap


def test_nothing_is_formatted_or_kept_while_nobody_reads():
    tap = InputTap()
    calls = []
    tap.publish("osc", lambda: calls.append(1) or "x")
    assert calls == [] and tap.read(1)[0] == []
    cursor = tap.attach()
    tap.publish("osc", lambda: calls.append(1) or "/vibsynth/intensity f 0.5")
    events, cursor, missed = tap.read(cursor)
    assert calls == [1] and [(e.source, e.text) for e in events] == [("osc", "/vibsynth/intensity f 0.5")]
    assert missed == 0 and tap.read(cursor)[0] == []


def test_errors_are_kept_for_status_whoever_listens():
    tap = InputTap()
    for k in range(ERRORS_KEPT + 5):
        tap.error(f"bad {k}")
    assert [e.text for e in tap.last_errors()] == [f"bad {k}" for k in range(5, ERRORS_KEPT + 5)]


def test_a_slow_reader_learns_what_it_missed_and_memory_stays_bounded():
    tap = InputTap(capacity=100)
    cursor = tap.attach()
    for k in range(250):
        tap.publish("midi", f"note {k}")
    events, cursor, missed = tap.read(cursor, limit=1000)
    assert missed == 150 and [e.text for e in events] == [f"note {k}" for k in range(150, 250)]
    assert len(tap._events) == 100


def test_long_texts_are_clipped():
    tap = InputTap()
    cursor = tap.attach()
    tap.publish("osc", "x" * 100_000)
    (event,), _, _ = tap.read(cursor)
    assert len(event.text) == MAX_TEXT and event.text.endswith("…")


def test_two_readers_each_see_everything_in_order_while_threads_publish():
    rng = np.random.default_rng(3)
    tap = InputTap(capacity=100_000)
    cursors = [tap.attach(), tap.attach()]
    per_thread = 2000

    def publish(name):
        for k in range(per_thread):
            tap.publish("osc", f"{name} {k}")

    threads = [threading.Thread(target=publish, args=(f"t{i}",)) for i in range(4)]
    for t in threads:
        t.start()
    seen = [[], []]
    while any(t.is_alive() for t in threads) or any(len(s) < 4 * per_thread for s in seen):
        for i in range(2):
            events, cursors[i], missed = tap.read(cursors[i], limit=int(rng.integers(1, 500)))
            assert missed == 0
            seen[i] += [e.text for e in events]
    for t in threads:
        t.join()
    assert seen[0] == seen[1] and len(seen[0]) == 4 * per_thread
    for name in ("t0", "t1", "t2", "t3"):  # each publisher's events arrive in its order
        mine = [int(s.split()[1]) for s in seen[0] if s.startswith(name + " ")]
        assert mine == list(range(per_thread))
    tap.detach()
    tap.detach()
    assert not tap.active


def test_the_flag_byte_says_whether_anyone_reads_and_late_publishers_keep_their_arrival_time():
    tap = InputTap(clock=lambda: 100.0)
    assert tap.flag == bytearray(b"\x00")
    first = tap.attach()
    tap.attach()
    tap.detach()
    assert tap.flag[0] == 1  # one reader left
    tap.publish("osc-fast", "/vibsynth/intensity f 0.3", at=99.5)
    tap.publish("osc", '/vibsynth/get s "intensity"')
    assert [(e.time, e.source) for e in tap.read(first)[0]] == [(99.5, "osc-fast"), (100.0, "osc")]
    tap.detach()
    assert tap.flag[0] == 0
