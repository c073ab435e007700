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
SIBLING = "sibling"  # a library only: another random family at the scene family's sizes
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


def library_builder(name: str | None, scene: ObjectBuilder, scene_seed: int, seed: int | None = None) -> ObjectBuilder:
    """The builder of a scene's model library: ``name`` of :func:`design_builder`, or ``None``
    (the scene's own ``scene``), or ``sibling``.

    ``seed`` is the library family's (default ``scene_seed``). ``sibling`` needs a random
    scene family: it is :func:`~sbsc_core.simulate.designs_random.sibling_family` of the
    family of ``seed`` (default ``scene_seed + 1``), another manufacturer's products at the
    scene's sizes.
    """
    if name is None:
        return scene
    if name != SIBLING:
        return design_builder(name, scene_seed if seed is None else seed)
    from .designs_random import RandomFamily, sibling_family

    if not isinstance(scene, RandomFamily):
        raise InputError("--library-designs", "sibling needs --designs random")
    return sibling_family(scene, scene_seed + 1 if seed is None else seed)
