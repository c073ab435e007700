"""Design sets of the simulator: which product designs the thirteen classes are built with.

``standard`` is :func:`objects.build_object` (the designs the method was developed on),
``alt`` is :func:`objects_alt.build_object_alt` (another manufacturer's products with the
same catalogue footprints), for measuring recognition on designs it was not tuned on;
``third`` is :func:`objects_third.build_object_third`, a third manufacturer used ONLY TO
TEST, never to tune (see that module); ``random`` is a new family per seed
(:func:`designs_random.random_family`), with sizes of its own.
A builder maps a class id to its :class:`~sbsc_core.simulate.mesh.ColouredMesh` in the
object-local frame; :func:`~sbsc_core.simulate.building.build_building` and
:func:`~sbsc_core.simulate.library.write_model_library` both take one.
"""

from __future__ import annotations

from ..errors import InputError
from .building import ObjectBuilder
from .objects import build_object
from .objects_alt import build_object_alt
from .objects_third import build_object_third

DESIGN_SETS: dict[str, ObjectBuilder] = {
    "standard": build_object,
    "alt": build_object_alt,
    "third": build_object_third,
}
DEFAULT_DESIGNS = "standard"
RANDOM = "random"  # a family drawn per seed (designs_random)
DESIGN_NAMES = (*DESIGN_SETS, RANDOM)


def design_builder(name: str | None, seed: int = 0) -> ObjectBuilder:
    """The object builder of design set ``name`` (``None`` = the standard set).

    ``random`` draws the family of ``seed`` (:func:`~sbsc_core.simulate.designs_random.random_family`);
    the fixed sets ignore ``seed``.
    """
    if name is None:
        name = DEFAULT_DESIGNS
    if name == RANDOM:
        from .designs_random import random_family

        return random_family(seed)
    try:
        return DESIGN_SETS[name]
    except KeyError:
        raise InputError("--designs", f"unknown design set {name!r} ({', '.join(DESIGN_NAMES)})") from None
