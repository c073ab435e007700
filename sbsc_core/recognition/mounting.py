"""Candidates that cannot be mounted where they were found.

A wall's orthoimage spans the wall from its floor (its bottom row) to its top, its own
room's ceiling (:mod:`sbsc_core.scene.segmentation`). An object of the library is mounted on
the wall, so its footprint lies between the two. A candidate whose footprint, at the
model's size and matched rotation, passes the floor or the top by more than a margin is
something else: typically furniture standing on the floor in front of the wall (a
waste bin or a cabinet whose relief a model correlates with, centred so low that the
model would reach into the floor). Such candidates are dropped before the consensus, so
that with expected counts they do not take a real object's place.
"""

from __future__ import annotations

from collections.abc import Iterable

from ..imaging.orthoimage import ortho_shape
from ..types import Candidate, Orthoimage

__all__ = ["within_wall_height"]


def within_wall_height(candidates: Iterable[Candidate], orthos: dict[str, Orthoimage], *,
                       margin_m: float) -> list[Candidate]:
    """The candidates whose footprint lies between their wall's floor and top, within ``margin_m``.

    Parameters
    ----------
    candidates
        Depth or colour candidates; ``box`` is the footprint in the wall's orthoimage
        (rows from the top, end exclusive), possibly reaching outside the image.
    orthos
        The orthoimage of each wall, by wall id (only its frame and pixel size are read: a
        parked orthoimage without its images will do). A candidate on a wall not listed is kept.
    margin_m
        How far (metres) a footprint may pass the floor or the top: the uncertainty of
        the two levels and of the footprint's edge.

    Returns
    -------
    list of Candidate
        The kept candidates, in their order.
    """
    kept = []
    for c in candidates:
        ortho = orthos.get(c.wall_id)
        if ortho is not None:
            slack = margin_m / ortho.pixel_m
            rows = ortho_shape(ortho.frame, ortho.pixel_m)[0]
            if c.box.r0 < -slack or c.box.r1 > rows + slack:
                continue
        kept.append(c)
    return kept
