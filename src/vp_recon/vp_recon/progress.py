"""Progress and cancel of a reconstruction: the stages reported, in order (:data:`STAGES`), the
callbacks' types, and :class:`ReconCancelled`, raised when the progress callback returns False."""
from __future__ import annotations

from typing import Callable, Optional

__all__ = ["STAGES", "ProgressFn", "ReconCancelled", "tick"]

#: Stages reported to the progress callback, in order.
STAGES = ("render", "sparse", "dense", "score")

#: progress(stage, realization) after each stage of each realization; returning False cancels.
ProgressFn = Callable[[str, int], Optional[bool]]


class ReconCancelled(Exception):
    """The progress callback returned False."""


def tick(progress: Optional[ProgressFn], stage: str, k: int) -> None:
    """``progress(stage, k)``; ReconCancelled when it returns False."""
    if progress is not None and progress(stage, k) is False:
        raise ReconCancelled(f"cancelled after {stage} of realization {k}")
