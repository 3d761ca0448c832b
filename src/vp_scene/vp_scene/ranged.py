"""Typed values that carry their ranges, and refusals with a code (ROS-free; the flight model of
:mod:`vp_planner.routes` and the geographic origin of :mod:`vp_scene.geo` are built on them).

A frozen dataclass declares each bounded field with :func:`bounded` (default, range, unit, help)
and calls :func:`check_ranges` once, in ``__post_init__``: a value that is not a finite number in
its range is refused with a :class:`CodedError` of the class's code, one line naming the field,
its value and its range. The ranges stay readable for the flags and parameters built from the
fields (:func:`range_text`).
"""
from __future__ import annotations

import math
from dataclasses import Field, field, fields
from typing import Any

__all__ = ["CodedError", "bounded", "check_ranges", "range_text"]


class CodedError(ValueError):
    """A refusal with its code and a one-line message (``str``: ``[CODE] message``)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code

    def __str__(self) -> str:
        return f"[{self.code}] {self.args[0]}"


def bounded(default: float, low: float, high: float, unit: str, help: str, low_open: bool = False) -> Any:
    """A dataclass field in [low, high] (``low_open``: (low, high]) with its unit and help."""
    return field(default=default, metadata={"range": (low, high), "low_open": low_open, "unit": unit, "help": help})


def range_text(f: Field) -> str:
    """The field's range as text, e.g. ``(0, 30] m/s``."""
    low, high = f.metadata["range"]
    return f"{'(' if f.metadata['low_open'] else '['}{low:g}, {high:g}] {f.metadata['unit']}".rstrip()


def check_ranges(obj: Any, code: str, error: type = CodedError, prefix: str = "") -> None:
    """``error(code, ...)`` for the first bounded field of ``obj`` that is not a finite number in its range."""
    for f in fields(obj):
        if "range" not in f.metadata:
            continue
        value, (low, high) = getattr(obj, f.name), f.metadata["range"]
        try:
            ok = math.isfinite(value) and (value > low if f.metadata["low_open"] else value >= low) and value <= high
        except TypeError:
            ok = False
        if not ok:
            raise error(code, f"{prefix}{f.name} must be in {range_text(f)}, got {value!r}")
