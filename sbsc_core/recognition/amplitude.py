"""How far a relief stands out, and whether a class's depth model can explain it.

Depth is metric: the orthoimage's relief above the wall plane says how far an object
stands out, and each class's depth model (contract 2) how far an object of that class does.
The depth recognizer accepts a scene / model amplitude ratio within its ``gain_range``; the
same range decides here, so that no other stage takes a place for a class that the relief
there rules out. A class taught from examples of the building (``sbsc learn``) knows more:
how far its instances stand out there, so a hit of it standing out further than its
examples, their spread and the scan's noise allow is refused (:func:`as_far_as_examples`).
Nothing in it is fitted to a design family: the figures are the given library's, the
examples' and the given scan's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..types import Candidate
from .matching import box_at, crop_padded

_AMPLITUDE_Q = 90.0  # a relief's amplitude: this percentile of how far it stands out (robust to noise and spikes)
_MIN_KNOWN = 0.5  # a footprint with a smaller share of known pixels has no measured amplitude


def relief_amplitude(relief: np.ndarray) -> float | None:
    """How far a relief (metres: a model's, or the scene's in a footprint) stands out: the
    :data:`_AMPLITUDE_Q` percentile of its absolute value over its known pixels.

    Returns
    -------
    float or None
        None when fewer than half of the pixels are known.
    """
    r = np.abs(np.asarray(relief, np.float64))
    ok = np.isfinite(r)
    if r.size == 0 or ok.sum() < _MIN_KNOWN * r.size:
        return None
    return float(np.percentile(r[ok], _AMPLITUDE_Q))


def scene_amplitude(relief: np.ndarray, shape: tuple[int, int], centre: tuple[float, float],
                    rotation_deg: float) -> float | None:
    """:func:`relief_amplitude` of the scene's ``relief`` in a footprint of ``shape`` (h, w
    pixels) centred at ``centre`` (row, col) and turned by ``rotation_deg`` (its sides swap
    when it is nearer a quarter turn than upright)."""
    h, w = shape
    if abs(((float(rotation_deg) + 45.0) % 180.0) - 45.0) > 45.0:
        h, w = w, h
    b = box_at(centre, h, w)
    return relief_amplitude(crop_padded(relief, b.r0, b.r1, b.c0, b.c1))


Models = dict[str, "np.ndarray | list[np.ndarray]"]  # class -> its depth model, or one per design


def designs(m: np.ndarray | list[np.ndarray]) -> list[np.ndarray]:
    """A class's models as a list: its one model, or one per design."""
    return list(m) if isinstance(m, list) else [m]


def amplitude_compatible(relief: np.ndarray, models: Models,
                         centres: dict[str, tuple[float, float]], rotation_deg: float,
                         gain_range: tuple[float, float]) -> dict[str, bool]:
    """For each class of ``models`` (depth models cropped to their content; a class with
    several designs is compatible when one of them is), whether the scene's relief in its
    footprint (at ``centres[c]``, turned by ``rotation_deg``) stands out as far as the model
    does, within ``gain_range`` (the depth recognizer's accepted scene / model amplitude ratio).

    An object whose relief stands out 16 mm is not a 2.5 mm flush socket nor a 45 mm call
    point, however alike their outlines and prints. A class whose amplitude cannot be
    measured here counts as compatible.
    """
    out = {}
    for c, designs_of in models.items():
        out[c] = False
        for m in designs(designs_of):
            own = relief_amplitude(m)
            seen = scene_amplitude(relief, m.shape[:2], centres[c], rotation_deg)
            if own is None or seen is None or own <= 0 or gain_range[0] <= seen / own <= gain_range[1]:
                out[c] = True
                break
    return out


@dataclass(frozen=True)
class FlatRefusal:
    """A colour candidate refused because the relief there is too flat for its class."""

    candidate: Candidate
    model_m: float  # how far its class's depth model stands out
    scene_m: float  # how far the scene does in its footprint


def colour_where_relief_allows(colour: list[Candidate], relief: np.ndarray | None, models: Models,
                               offsets: dict[str, tuple[float, float]], gain_range: tuple[float, float]
                               ) -> tuple[list[Candidate], list[FlatRefusal]]:
    """The colour candidates whose class's depth model the relief in their footprint does not
    rule out, and the refused ones.

    A colour candidate of a class that stands out (its depth model, ``models``, cropped to
    its content whose centre lies ``offsets`` from the footprint's) at a place where the
    scene stands out less than ``gain_range[0]`` times as far is a print without its object:
    a specular highlight or a poster's white square taken for a flush socket. The relief is
    measured where it is known (:func:`scene_amplitude`); noise only raises it, so a noisy
    scan refuses less, never more. Classes without a depth model, and places seen too
    sparsely to measure, are kept; a class with several designs is refused only when the
    relief is too flat for every one of them.
    """
    if relief is None or not colour:
        return colour, []
    kept: list[Candidate] = []
    refused: list[FlatRefusal] = []
    centre_of = lambda cand: shifted_centre(cand.centre, offsets.get(cand.class_id), cand.rotation_deg)  # noqa: E731
    for cand in colour:
        flat: list[FlatRefusal] = []
        per_design = designs(models[cand.class_id]) if cand.class_id in models else []
        for m in per_design:
            own = relief_amplitude(m)
            seen = None if own is None or own <= 0 else scene_amplitude(relief, m.shape[:2], centre_of(cand),
                                                                        cand.rotation_deg)
            if seen is None or seen >= gain_range[0] * own:
                break
            flat.append(FlatRefusal(cand, own, seen))
        if per_design and len(flat) == len(per_design):
            refused.append(flat[0])
        else:
            kept.append(cand)
    return kept, refused


EXAMPLE_RELIEF_KEY = "example_relief_m"  # model.json: how far each example stands out (sbsc learn)


def example_amplitudes(extra: dict) -> list[float]:
    """How far the examples of a class stood out in the scan they were taught from
    (``model.json`` :data:`EXAMPLE_RELIEF_KEY`, written by ``sbsc learn``); [] when the class
    was not taught or the entry is not a list of positive numbers."""
    vals = extra.get(EXAMPLE_RELIEF_KEY)
    if not isinstance(vals, list) or not vals:
        return []
    ok = [float(v) for v in vals if isinstance(v, int | float) and not isinstance(v, bool) and float(v) > 0]
    return ok if len(ok) == len(vals) else []


def taught_amplitudes(templates: dict) -> dict[str, tuple[tuple[int, int], list[float]]]:
    """class -> (footprint (h, w) pixels, its examples' amplitudes) of the classes of
    ``templates`` (:class:`~sbsc_core.recognition.templates.ModelTemplate`) taught from
    examples (:func:`example_amplitudes`); {} for a library that was not taught."""
    out = {}
    for c, t in templates.items():
        amps = example_amplitudes(t.extra)
        if amps:
            out[c] = ((int(t.height_px), int(t.width_px)), amps)
    return out


def example_limit(amplitudes: list[float], noise_m: float) -> float:
    """How far an instance of a class taught from examples may stand out: its furthest example,
    plus the examples' own spread (the furthest minus the nearest: how much this building's
    instances were seen to differ), plus ``noise_m`` (the wall's noise relief, the smallest relief
    the depth recognizer tells from its plain wall,
    :func:`~sbsc_core.recognition.depth_recognition.noise_relief`: a difference smaller than
    that is no evidence).

    The examples are instances of the class in this building, measured in a scan of it: unlike
    a library's model of some product of the class (whose amplitude the scene may exceed by
    ``gain_range``'s generic 2x), they say how far its instances stand out. Nothing in it is
    a design family's figure: the examples' and the scan's only.
    """
    return max(amplitudes) + (max(amplitudes) - min(amplitudes)) + float(noise_m)


@dataclass(frozen=True)
class TallRefusal:
    """A candidate refused because the relief there stands out further than every example of
    its class did, beyond their spread and the scan's noise (:func:`example_limit`)."""

    candidate: Candidate
    examples_m: float  # how far the class's examples stood out (the furthest)
    limit_m: float  # how far an instance may stand out (example_limit)
    scene_m: float  # how far the scene does in its footprint


def as_far_as_examples(cands: list[Candidate], relief: np.ndarray | None,
                       taught: dict[str, tuple[tuple[int, int], list[float]]],
                       noise_m: float) -> tuple[list[Candidate], list[TallRefusal]]:
    """The candidates (depth or colour) whose footprint stands out no further than their
    class's :func:`example_limit`, and the refused ones.

    ``taught``: class -> (footprint (h, w) pixels, the amplitudes of its examples,
    :func:`example_amplitudes`); ``noise_m``: the wall's noise relief. Only classes taught
    from examples of this building take part: their examples measured, in a scan of this
    building with its noise, how far its instances stand out. A match where the scene stands
    out further is another object of that size: a flush built-in socket's print on a 20 mm
    room controller (colour), or a switch whose examples stood out 11 mm matched by depth on
    a 22 mm room controller, which the depth recognizer's generic ``gain_range`` (2x a
    library model of another product) lets through. Without examples the check is one-sided
    (:func:`colour_where_relief_allows`): a library's model of another product says nothing
    certain about how far this building's stands out, and noise raises a scene's amplitude.
    The amplitude is measured over the class's footprint, as the examples' was; a place seen
    too sparsely to measure is kept.
    """
    if relief is None or not cands or not taught:
        return cands, []
    kept: list[Candidate] = []
    refused: list[TallRefusal] = []
    for cand in cands:
        if cand.class_id in taught:
            shape, amps = taught[cand.class_id]
            limit = example_limit(amps, noise_m)
            seen = scene_amplitude(relief, shape, cand.centre, cand.rotation_deg)
            if seen is not None and seen > limit:
                refused.append(TallRefusal(cand, max(amps), limit, seen))
                continue
        kept.append(cand)
    return kept, refused


def shifted_centre(centre: tuple[float, float], offset: tuple[float, float] | None,
             rotation_deg: float) -> tuple[float, float]:
    """``centre`` moved by ``offset`` (row, col) turned by ``rotation_deg``."""
    if offset is None or (offset[0] == 0 and offset[1] == 0):
        return centre
    a = np.deg2rad(float(rotation_deg))
    dr, dc = offset
    return (centre[0] + dr * np.cos(a) - dc * np.sin(a), centre[1] + dr * np.sin(a) + dc * np.cos(a))
