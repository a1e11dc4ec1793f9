"""Arguments of the public API checked where they come in: a value of the
wrong type raises ``TypeError``, a value out of its domain ``ValueError``;
either names the argument first (``l must be a finite number, got str
'1'``). The extension module checks what it is given too (array shapes,
ranges); these turn Python values into what it takes."""

from __future__ import annotations

import json
import math
import numbers
import os
from pathlib import Path
from typing import Any

import numpy as np


def describe(x: Any) -> str:
    """``str '1'``, ``NoneType``, ``list [['a', 'b']]``: a value for a message."""
    if x is None:
        return "None"
    text = repr(x)
    if len(text) > 40:
        text = text[:37] + "..."
    return f"{type(x).__name__} {text}"


def number(name: str, x: Any, *, finite: bool = False) -> float:
    """``x`` as a float: a real number (a Python or numpy int or float; not
    a bool, not text); with ``finite``, not NaN or infinite."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        what = "a finite number" if finite else "a number"
        raise TypeError(f"{name} must be {what}, got {describe(x)}")
    v = float(x)
    if finite and not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, got {v}")
    return v


def optional_number(name: str, x: Any) -> float | None:
    """None, or :func:`number`."""
    return None if x is None else number(name, x)


def integer(name: str, x: Any, *, low: int = 0, high: int = 2**64) -> int:
    """``x`` as an int in ``[low, high)``: a Python or numpy integer (not a
    bool, not a float)."""
    if isinstance(x, bool) or not isinstance(x, numbers.Integral):
        raise TypeError(f"{name} must be a whole number, got {describe(x)}")
    v = int(x)
    if not low <= v < high:
        raise ValueError(f"{name} must be a whole number in [{low}, {_power(high)}), got {v}")
    return v


def optional_integer(name: str, x: Any, *, low: int = 0) -> int | None:
    """None, or :func:`integer`."""
    return None if x is None else integer(name, x, low=low)


def flag(name: str, x: Any) -> bool:
    """``x`` as a bool: True or False (a numpy bool too)."""
    if not isinstance(x, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {describe(x)}")
    return bool(x)


def text(name: str, x: Any) -> str:
    """``x``, a str."""
    if not isinstance(x, str):
        raise TypeError(f"{name} must be a str, got {describe(x)}")
    return x


def path(name: str, x: Any) -> Path:
    """``x`` as a Path: a str or an os.PathLike."""
    if not isinstance(x, (str, os.PathLike)):
        raise TypeError(f"{name} must be a path (a str or an os.PathLike), got {describe(x)}")
    return Path(x)


def optional_path(name: str, x: Any) -> Path | None:
    """None, or :func:`path`."""
    return None if x is None else path(name, x)


def array(name: str, x: Any, *, ndim: int | None = None, shape: str = "") -> np.ndarray:
    """``x`` as a C-contiguous float64 array: numbers (ints or floats, in a
    numpy array or nested lists; not text, None or bools). With ``ndim``,
    of that many dimensions (``shape`` says which in the message: ``(n,
    2)``)."""
    want = f"an array of numbers{f' of shape {shape}' if shape else ''}"
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError) as e:  # ragged nesting
        raise TypeError(f"{name} must be {want}, got {describe(x)} ({e})") from None
    if raw.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be {want}, got {describe(x)}")
    if ndim is not None and raw.ndim != ndim:
        raise ValueError(f"{name} must be {want}, got one of shape {raw.shape}")
    return np.ascontiguousarray(raw, dtype=np.float64)


def robot_json(name: str, robot: Any) -> str:
    """A robot's eq. 3 parameters as JSON: a preset's name or a mapping of
    them (as ``Simulation.agents[i]["robot"]``)."""
    from collections.abc import Mapping

    from . import _echelon

    if isinstance(robot, str):
        return _echelon.robot_preset(robot)
    if not isinstance(robot, Mapping):
        raise TypeError(
            f"{name} must be a robot preset's name or a dict of eq. 3's parameters, got {describe(robot)}"
        )
    try:
        return json.dumps(dict(robot), allow_nan=True)
    except (TypeError, ValueError) as e:
        raise TypeError(f"{name}: {e}") from None


def _power(x: int) -> str:
    """``2**64`` for 2**64: a bound in short form."""
    k = x.bit_length() - 1
    return f"2**{k}" if x == 1 << k and k > 16 else str(x)
