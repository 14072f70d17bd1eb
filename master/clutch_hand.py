"""The scripted hand's clutch button (:class:`ClutchHand`): what a simulated operator does when the console asks
it to align, after a fault moved the hand or the slave relaxed (:mod:`master.console`): it presses the clutch for a
moment and lets go, which re-anchors the master where the hand is."""
from __future__ import annotations

__all__ = ["ClutchHand"]


class ClutchHand:
    """The scripted hand's clutch button: when the console asks to align (status ALIGN), the hand
    presses button ``bit`` for ``hold`` [s] and lets go, which re-anchors the master where the hand
    is. A negative ``bit``: the hand never clutches. ``count`` is the number of presses."""

    def __init__(self, bit: int, hold: float):
        self.bit, self.hold = int(bit), float(hold)
        self.count = 0
        self._wanted = False
        self._until: float | None = None    # [s] end of the press under way

    def on_console(self, status) -> None:
        """ALIGN asks for one press (not while one is under way)."""
        if getattr(status, "name", status) == "ALIGN" and self._until is None and self.bit >= 0:
            self._wanted = True

    def buttons(self, t: float) -> int:
        """The button bits at time ``t`` [s]: ``1 << bit`` while pressed, else 0."""
        if self._wanted:
            self._wanted, self._until = False, t + self.hold
            self.count += 1
        if self._until is not None:
            if t < self._until:
                return 1 << self.bit
            self._until = None
        return 0
