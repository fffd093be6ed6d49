"""The last float calculation of a system, by the bytes of what it was computed from.

Drake's RK5 (Dormand and Prince's 5(4)) evaluates the derivative at the state it
accepts as its seventh stage, and the next step's first stage evaluates it again at
that same time and state: the step's end moves the context's state, which marks every
cache entry out of date, so Drake recomputes what it had (one evaluation in seven, 14%
of a UR5 run's). A system's hot float calculation keeps its last result with the exact
bytes of its inputs and parameters (:class:`LastCall`): the same bytes again return that
result, and the repeat costs Drake's share and the port reads only. Bit for bit the same
run: a result is a function of those bytes alone (NaN in, the NaN result out again).

Float only: an AutoDiffXd or Expression system computes every call (its values carry
derivatives or symbols, which bytes do not name). :data:`ENABLED` turns every memo off
(the tests run a loop both ways).
"""

from __future__ import annotations

__all__ = ["ENABLED", "LastCall"]

#: Whether :class:`LastCall` recalls at all (False: every call computes; for the tests).
ENABLED = True


class LastCall:
    """One calculation's last ``(key, value)``; ``hits`` counts the recalls."""

    __slots__ = ("_key", "_value", "hits")

    def __init__(self) -> None:
        self._key: bytes | None = None
        self._value: object = None
        self.hits = 0

    def get(self, key: bytes) -> object:
        """The value last stored with exactly ``key``, else None."""
        if key == self._key and ENABLED:
            self.hits += 1
            return self._value
        return None

    def put(self, key: bytes, value: object) -> object:
        """Keep ``value`` (never mutated afterwards) for ``key``; returns it."""
        self._key, self._value = key, value
        return value
