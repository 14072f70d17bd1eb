"""The console's shared clutch of a bimanual master: one foot pedal for both hands.

A surgeon at a bimanual console clutches with a foot pedal: while it is held neither hand drives its
arm, and on its release each hand's map re-anchors where the hand is (:mod:`master.console`). Here
the pedal is the clutch button bit (``master.mapping.clutch_button``) of *either* hand's device: a
real console's pedal wired as a button of one device, a button on each handle, or the scripted
operators' presses (each scripted hand presses it when its console asks to align, as a surgeon
presses the pedal). :class:`FootPedal` keeps each hand's last reading of that bit; :class:`PedalHand`
wraps one hand's device so that its reading carries the pedal (the OR over the hands) in that bit
and nothing else changes: the deadman (``operator_present``) stays the hand's own, and everything
else (forces, ``watch``, ``finished``, ``marker`` ...) goes to the hand's device untouched.

A hand sees the other hand's bit as read in its latest cycle: within one loop period (1 ms).
"""
from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["FootPedal", "PedalHand"]


class FootPedal:
    """The shared clutch: pressed while any hand's device holds its clutch bit.

    Parameters
    ----------
    bits : sequence of int
        Each hand's clutch button bit (its ``master.mapping.clutch_button``; < 0: that hand has none).

    Attributes
    ----------
    masks : tuple of int
        Each hand's clutch bit mask (0: none).
    presses : int
        Presses seen (released -> pressed).
    """

    def __init__(self, bits):
        self.masks = tuple(1 << int(b) if int(b) >= 0 else 0 for b in bits)
        self._held = [False] * len(self.masks)
        self._pressed = False
        self.presses = 0

    @property
    def pressed(self) -> bool:
        """Whether the pedal is held now (any hand's bit at its latest reading)."""
        return self._pressed

    def note(self, hand: int, buttons: int) -> bool:
        """Record hand ``hand``'s button bits ``buttons``; returns whether the pedal is held."""
        self._held[hand] = bool(buttons & self.masks[hand])
        pressed = any(self._held)
        self.presses += pressed and not self._pressed
        self._pressed = pressed
        return pressed


class PedalHand:
    """One hand's device whose readings carry the shared pedal in the clutch bit (module docstring).

    Parameters
    ----------
    device : the hand's haptic device (``read(t)`` -> a state with ``buttons``).
    pedal : FootPedal
    hand : int
        This hand's index in ``pedal`` (0 or 1).
    """

    def __init__(self, device: Any, pedal: FootPedal, hand: int):
        self.inner = device
        self.pedal = pedal
        self.hand = int(hand)

    def read(self, t: float) -> Any:
        """The device's reading at ``t`` [s] with the clutch bit set while the pedal is held."""
        st = self.inner.read(t)
        mask = self.pedal.masks[self.hand]
        if not mask:
            return st
        held = self.pedal.note(self.hand, st.buttons)
        buttons = (st.buttons | mask) if held else (st.buttons & ~mask)
        return st if buttons == st.buttons else dataclasses.replace(st, buttons=buttons)

    def __getattr__(self, name: str) -> Any:
        if name == "inner":             # not set yet (copying, unpickling): no recursion
            raise AttributeError(name)
        # everything but read goes to the hand's device (set_force(s), watch, on_console, finished, close ...)
        return getattr(self.inner, name)
