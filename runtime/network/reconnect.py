"""When a peer connects again to the peers it must link to (thesis §3.1.4.2, ``<Network reconnectMin/Max>``).

In the full mesh the lower GUID connects to the higher one. :class:`ReconnectSchedule` keeps, for
each higher peer discovery knows, when the next attempt is due: at once when the peer is found,
then after a back-off doubling from ``reconnectMin`` up to ``reconnectMax`` while attempts fail,
back to ``reconnectMin`` once a link opens. It holds no lock of its own: the peer calls it under
its lock.
"""

from __future__ import annotations

from collections.abc import Container


class ReconnectSchedule:
    """The due times and back-offs of the connection attempts of one peer (§3.1.4.2)."""

    def __init__(self, minimum: float, maximum: float) -> None:
        self.minimum, self.maximum = minimum, maximum
        self._retry_at: dict[int, float] = {}
        self._backoff: dict[int, float] = {}
        self._connecting: set[int] = set()

    def found(self, guid: int) -> None:
        """``guid`` was discovered: try it at once, from the shortest back-off."""
        self._retry_at[guid] = 0.0
        self._backoff[guid] = self.minimum

    def forget(self, guid: int) -> None:
        """No attempt is due for ``guid`` (lost by discovery)."""
        self._retry_at.pop(guid, None)

    def linked(self, guid: int) -> None:
        """A link to ``guid`` opened: no attempt due, the back-off starts again from the shortest."""
        self._retry_at.pop(guid, None)
        self._backoff[guid] = self.minimum

    def retry(self, guid: int, now: float) -> None:
        """An attempt or the link to ``guid`` failed: try again after the back-off, and double it."""
        delay = self._backoff.get(guid, self.minimum)
        self._retry_at[guid] = now + delay
        self._backoff[guid] = min(delay * 2, self.maximum)

    def due(self, now: float, linked: Container[int]) -> list[int]:
        """The peers to connect to now (none linked or already connecting); marked as connecting."""
        due = [g for g, at in self._retry_at.items() if at <= now and g not in linked]
        due = [g for g in due if g not in self._connecting]
        for guid in due:
            self._retry_at.pop(guid, None)
            self._connecting.add(guid)
        return due

    def pending(self) -> bool:
        """Whether an attempt is scheduled or under way (the peer's timer then looks often)."""
        return bool(self._retry_at or self._connecting)

    def attempted(self, guid: int) -> None:
        """The attempt to connect to ``guid`` is over (the link, if any, goes on by itself)."""
        self._connecting.discard(guid)
