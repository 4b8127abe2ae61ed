"""A broadcast hub: the newest message to every viewer, old ones dropped for slow viewers.

Every viewer has a mailbox holding at most one message.  A new viewer gets
the latest message while others watch; with nobody watching, nothing is
published, and the latest message is forgotten as the last viewer leaves, so
that the next one is not shown a state from then.  Publishing replaces
an unread message (the viewer drops a frame) instead of waiting, so a slow or
stalled viewer never holds the others up.  All methods run on the server's
event loop thread.
"""

from __future__ import annotations

import asyncio

__all__ = ["Hub", "Mailbox"]


class Mailbox:
    """One viewer's slot: the newest unread message, and how many were dropped."""

    def __init__(self) -> None:
        self._queue: asyncio.Queue[str] = asyncio.Queue(maxsize=1)
        self.dropped = 0
        self.delivered = 0

    def put(self, message: str) -> None:
        """Leave ``message``, replacing an unread one."""
        if self._queue.full():
            self._queue.get_nowait()
            self.dropped += 1
        self._queue.put_nowait(message)

    async def get(self) -> str:
        """Wait for the next message."""
        message = await self._queue.get()
        self.delivered += 1
        return message


class Hub:
    """The set of viewers and the latest message."""

    def __init__(self) -> None:
        self._boxes: set[Mailbox] = set()
        self.latest: str | None = None
        self.published = 0

    @property
    def viewers(self) -> int:
        """Number of connected viewers."""
        return len(self._boxes)

    def subscribe(self) -> Mailbox:
        """A new viewer's mailbox, primed with the latest message."""
        box = Mailbox()
        if self.latest is not None:
            box.put(self.latest)
        self._boxes.add(box)
        return box

    def unsubscribe(self, box: Mailbox) -> None:
        """Forget a viewer; the last one gone, the latest message too (it goes stale)."""
        self._boxes.discard(box)
        if not self._boxes:
            self.latest = None

    def publish(self, message: str) -> None:
        """Give ``message`` to every viewer without waiting for any."""
        self.latest = message
        self.published += 1
        for box in self._boxes:
            box.put(message)
