"""The pipeline's stages: one name each, in the order a run reports them.

A run calls ``progress(stage, fraction)`` with one of these (the CLI draws a bar per stage, the
review app turns them into one overall fraction). Nothing else spells a stage's name.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum


class Stage(StrEnum):
    """A stage of ``sbsc detect``, in running order (a ``str``: ``Stage.WALLS == "walls"``)."""

    READING = "reading"
    SEGMENTATION = "segmentation"
    PARTITION = "partition"
    WALLS = "walls"
    CEILINGS = "ceilings"
    COLUMNS = "columns"
    CONSENSUS = "consensus"
    WRITING = "writing"
    DONE = "done"


# The share of a typical run each stage takes (they add up to 1); ``DONE`` takes none.
STAGE_SHARE: dict[Stage, float] = {
    Stage.READING: 0.138, Stage.SEGMENTATION: 0.074, Stage.PARTITION: 0.085, Stage.WALLS: 0.479,
    Stage.CEILINGS: 0.053, Stage.COLUMNS: 0.053, Stage.CONSENSUS: 0.074, Stage.WRITING: 0.044,
    Stage.DONE: 0.0,
}

Progress = Callable[[str, float], None]
"""``progress(stage, fraction)``: ``stage`` a :class:`Stage`, ``fraction`` of it done (0..1)."""


def no_progress(stage: str, fraction: float) -> None:
    """The progress callback that reports nothing."""
    return None


def stage_spans(start: float, end: float) -> dict[str, tuple[float, float]]:
    """Each stage's span of an overall progress running from ``start`` to ``end``.

    Parameters
    ----------
    start, end
        The overall fraction at the first stage's start and at :attr:`Stage.DONE`.

    Returns
    -------
    dict
        ``{stage: (lo, hi)}`` for every :class:`Stage`, contiguous and in running order.
    """
    spans, lo = {}, start
    for stage in Stage:
        hi = lo + (end - start) * STAGE_SHARE[stage]
        spans[stage.value] = (lo, hi)
        lo = hi
    return spans
