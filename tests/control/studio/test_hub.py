"""The studio's push path: the newest message per key, bounded memory whatever the rate."""

from __future__ import annotations

import asyncio
import threading

from vibsynth.control.studio.hub import MAX_KEYS, Hub


def test_a_flood_from_many_threads_keeps_one_message_per_key():
    async def scenario():
        hub = Hub(asyncio.get_running_loop())

        def flood(thread: int) -> None:
            for n in range(20_000):
                hub.post(("knob", n % 4), {"thread": thread, "n": n})

        threads = [threading.Thread(target=flood, args=(t,)) for t in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert len(hub._incoming) <= 4  # noqa: SLF001 - the bound is the point of the test
        await asyncio.sleep(0)  # let the scheduled dispatch run
        return hub

    hub = asyncio.run(scenario())
    assert hub.posted == 80_000 and hub.dropped == 0
    assert hub._incoming == {}  # noqa: SLF001


def test_distinct_keys_beyond_the_cap_are_dropped_and_counted():
    async def scenario():
        hub = Hub(asyncio.get_running_loop())
        for n in range(MAX_KEYS + 10):
            hub.post(("ext", n), {"n": n})
        return hub

    hub = asyncio.run(scenario())
    assert hub.dropped == 10


def test_posting_after_the_loop_closed_is_harmless():
    loop = asyncio.new_event_loop()
    hub = Hub(loop)
    loop.close()
    hub.post(("knob", 0), {"v": 1})  # the service is stopping: nothing to do, nothing raised
    assert hub.posted == 1
