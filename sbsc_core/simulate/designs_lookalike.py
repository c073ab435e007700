"""Development designs with LOOK-ALIKE signs: the standard or alt set, but both signs are
same-size square red plates with the set's own pictograms.

In the ``standard`` and ``alt`` sets the extinguisher sign (0.21 x 0.30 m) and the call
point sign (0.21 x 0.21 m) differ in size, so the paper's recognizers tell them apart by
their extent. Real products often do not: both are square plates of one size, and only the
pictogram differs. These builders make that case from the development designs, so that the
look-alike step (:mod:`sbsc_core.recognition.lookalikes`) can be developed and tested without ever
looking at the ``third`` set (which is for testing only).

Each plate is ``side_m`` square, centred in its class's catalogue footprint (as products
of another size sit in a footprint), with the set's pictogram drawn for a square sign.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from . import pictograms as pg
from . import pictograms_alt as pga
from .building import ObjectBuilder
from .catalogue import CATALOGUE
from .mesh import ColouredMesh, box, merge, quad
from .objects import build_object
from .objects_alt import build_object_alt

SIGNS = ("extinguisher_sign", "fire_alarm_switch_sign")
EPS = 0.0004


def square_sign(class_id: str, draw: Callable[[float, float], np.ndarray], red: tuple[int, int, int],
                *, side_m: float = 0.20) -> ColouredMesh:
    """A ``side_m`` square plate of ``class_id``'s depth with ``draw(side, side)`` on its front."""
    d = CATALOGUE[class_id].depth_m
    return merge([box((side_m, side_m, d), red, (0.0, 0.0, d / 2)),
                  quad((-side_m / 2, -side_m / 2, d + EPS), (side_m, 0, 0), (0, side_m, 0),
                       texture=draw(side_m, side_m))])


def lookalike_builder(base: str, *, side_m: float = 0.20) -> ObjectBuilder:
    """The ``base`` design set (``standard`` or ``alt``) with same-size square signs."""
    if base == "standard":
        build, pic, red = build_object, pg, pg.SAFETY_RED
    elif base == "alt":
        build, pic, red = build_object_alt, pga, pga.SIGN_RED
    else:
        raise ValueError(f"look-alike signs are made from 'standard' or 'alt', not {base!r}")
    draws = {"extinguisher_sign": pic.extinguisher_sign, "fire_alarm_switch_sign": pic.fire_alarm_sign}

    def builder(class_id: str) -> ColouredMesh:
        if class_id in draws:
            return square_sign(class_id, draws[class_id], tuple(red), side_m=side_m)
        return build(class_id)

    return builder
