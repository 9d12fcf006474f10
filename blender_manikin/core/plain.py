"""Plain Python values for user-facing messages, identical on numpy 1.x and 2.x.

numpy 2 changed the ``repr`` of its scalars: ``repr(np.str_('hand_l'))`` is ``"np.str_('hand_l')"``
and ``repr(np.float64(30.0))`` is ``'np.float64(30.0)'`` (numpy 1 gave ``'hand_l'`` and ``30.0``).
Every message that quotes a value with ``!r`` or ``repr`` (directly, or inside a list or dict) goes
through :func:`shown`, so Blender 4.2-5.0 (numpy 1) and 5.1+ (numpy 2) print the same text.
"""
from __future__ import annotations

import numpy as np

__all__ = ["plain", "shown"]


def plain(value):
    """``value`` with numpy scalars and arrays turned into Python builtins, recursively through
    lists, tuples, sets and dicts (``np.str_('a')`` -> ``'a'``, ``np.float64(1.5)`` -> ``1.5``,
    ``np.array([1, 2])`` -> ``[1, 2]``)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {plain(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return type(value)(plain(v) for v in value)
    return value


def shown(value) -> str:
    """``repr`` of :func:`plain` ``(value)``: how a message quotes a value."""
    return repr(plain(value))
