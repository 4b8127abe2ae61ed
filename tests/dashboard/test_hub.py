"""The broadcast hub: every viewer gets the newest message; a stalled one drops, never blocks."""

from __future__ import annotations

import asyncio

from relaxgrip.dashboard.hub import Hub


def test_stalled_viewer_drops_frames_and_never_blocks_others() -> None:
    async def scenario() -> tuple[list[str], int, int]:
        hub = Hub()
        fast, stalled = hub.subscribe(), hub.subscribe()
        got: list[str] = []
        for k in range(50):
            hub.publish(f"m{k}")
            got.append(await asyncio.wait_for(fast.get(), 1.0))
        last = await asyncio.wait_for(stalled.get(), 1.0)
        hub.unsubscribe(stalled)
        hub.publish("after")
        assert hub.viewers == 1
        return [*got, last], stalled.dropped, fast.dropped

    got, dropped_stalled, dropped_fast = asyncio.run(scenario())
    assert got[:50] == [f"m{k}" for k in range(50)]
    assert got[50] == "m49"  # the stalled viewer only sees the newest
    assert dropped_stalled == 49
    assert dropped_fast == 0


def test_new_viewer_gets_the_latest_message_at_once() -> None:
    async def scenario() -> str:
        hub = Hub()
        hub.publish("old")
        hub.publish("new")
        return await asyncio.wait_for(hub.subscribe().get(), 1.0)

    assert asyncio.run(scenario()) == "new"


def test_the_latest_message_is_forgotten_as_the_last_viewer_leaves() -> None:
    """Nobody watching, nothing is published: the next viewer must not see a stale state."""
    hub = Hub()
    box = hub.subscribe()
    hub.publish("while watched")
    other = hub.subscribe()
    assert hub.latest == "while watched"
    hub.unsubscribe(box)
    assert hub.latest == "while watched"  # one viewer still there
    hub.unsubscribe(other)
    gone: object = hub.latest
    assert gone is None
    assert hub.subscribe()._queue.empty()
