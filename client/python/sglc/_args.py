"""Checks of the integer arguments of sglc.Client's calls, before anything is sent."""
from __future__ import annotations

import operator


def integer(name: str, value) -> int:
    """`value` as an int when it is an integer: a Python int or a NumPy integer (anything with __index__), not a
    bool. A float (even 2.0), a string or a bool raises TypeError naming the argument: int(1.5) would silently be
    1, int("7") would hide a caller's mix-up."""
    if isinstance(value, bool) or (hasattr(value, "dtype") and value.dtype.kind == "b"):
        raise TypeError(f"{name} must be an integer, not a bool ({value!r})")
    try:
        return operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an integer, not {type(value).__name__} ({value!r:.40})") from None
