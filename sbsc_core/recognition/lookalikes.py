"""Look-alike classes, told apart at the level of the pictogram (issue 13, item 1).

Two classes are look-alikes when the library itself says that the paper's recognizers
cannot tell them apart: objects of the same size (``size_tolerance``), depth models that
correlate highly with each other (``min_depth_ncc``, best of the quarter turns; two flat
plates correlate ~1) and colour footprints of about the same mean colour
(``max_colour_delta_e``, CIE76 in Lab). Size and depth are those of the model's content
(:func:`content_box`: its colour view's alpha, else its relief), not of the catalogue
footprint it was given: a 0.20 m square plate in a 0.21 x 0.30 m footprint and the same
plate in a 0.21 x 0.21 m one look alike on a wall. An extinguisher sign and a fire-alarm call-point
sign, both square red plates, are such a pair: depth correlates 0.94-0.97 with either and
the 15 global colour descriptors are alike.

With ``depth_alike_any_colour`` (the default), same-size classes whose depth models correlate
at least ``min_depth_ncc`` are look-alikes whatever their mean colours: the depth recognizer
cannot tell them apart, and the colour recognizer, which could, does not always find the
object (a red call point whose relief correlates 0.95 with a white smoke detector's was found
in depth only, as a smoke detector). Their prints then decide at every depth candidate, as
for any look-alikes.

For a candidate of a class in such a set, the colour orthoimage patch (Lab difference to
the local wall colour, the foreground only: what the colour recognizer sees) is compared
with each class's front view as seen on that wall (:class:`~sbsc_core.recognition.colour_recognition.
WallPrototype`, cropped to the content), at the candidate's position (within ``search_px``) and turn (and its
quarter turns: a square plate's relief does not tell them), by normalised
cross-correlation: the pictogram decides. A candidate whose own class's print correlates
less than another look-alike's by more than ``min_margin`` is relabelled to that class,
provided that print does correlate (``min_print_ncc``: a white switch on a white wall
shows too little of its print to decide anything).
The margin (own print minus the best other look-alike's) is kept on the candidate.

With ``relief_decides``, same-size classes of about the same mean colour whose depth models
both vary inside their content are look-alikes whatever their depth correlation (a white
switch and a white one-gang socket: 0.88 in one design set, 0.92 in another): the fine
relief below tells them apart.

Classes are also look-alikes on a wall where the colour classifier cannot tell them apart
(:func:`colour_confusable`): same-size objects whose wall prototypes lie within mu_C of each
other (a white switch and a white one-gang socket on a white wall), whatever their depth
models. For such classes the print alone is weak (little of a white plate differs from a
white wall), so the fine relief decides with it (:func:`relief_score`): the NCC of each
class's depth model, cropped to its content, with the relief above the wall at the
candidate's place and turn, at the full resolution (the socket's cup, the switch's rocker).
A class's evidence is the mean of the comparisons available for every class of the set;
with the relief in it, the better class is taken at a smaller margin and level
(``min_margin_relief``, ``min_evidence_relief``): two independent comparisons agree.
Its margin is then taken over ``min_evidence_relief`` as well as over the other classes: a
room controller that fits the switch a little better than the socket, and both badly, has
a small or negative margin (the confidence reads it).

Depth is metric, so a look-alike decision never contradicts the relief's amplitude
(:func:`amplitude_compatible`): a class whose depth model stands out more or less than the
scene does at the candidate, by more than the depth recognizer's own ``gain_range``, is not
one of the classes the candidate may be, whatever its print says. Both figures come from
the given library and scan (how far each class's model stands out; how far the scene does
there), so a library of a design never seen is served as well as ours: an outside design's
tilted rocker switch (8-16 mm) is no longer taken for its flush built-in socket (2.5 mm) or
its call point (45 mm) because their prints correlated better on a low-contrast wall.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import cv2
import numpy as np

from ..settings import LookalikeSettings
from ..types import Box, Candidate
from .amplitude import amplitude_compatible, designs
from .amplitude import shifted_centre as _shifted
from .colour_recognition import ColourImage, ColourPrototypes, prototype_distance
from .matching import box_at, crop_padded, ncc_map, nms, padded_template, rotate_template
from .templates import ModelTemplate


def content_box(t: ModelTemplate) -> Box:
    """The part of a model's footprint that is the object: the bounding box of its colour
    view's alpha (else of its depth relief above a fifth of the largest), in footprint pixels.

    A product smaller than its catalogue footprint (a 0.20 m plate in a 0.21 x 0.30 m
    footprint) is compared by what it is, not by the footprint it was given.
    """
    mask = None
    if t.colour_views:
        mask = t.colour_views[0][..., 3] > 127
    if (mask is None or not mask.any()) and t.depth is not None:
        d = np.abs(t.depth_filled())
        mask = d > 0.2 * float(d.max()) if float(d.max()) > 0 else None
    if mask is None or not mask.any():
        return Box(0, 0, t.height_px, t.width_px)
    rr, cc = np.nonzero(mask)
    return Box(int(rr.min()), int(cc.min()), int(rr.max()) + 1, int(cc.max()) + 1)


def content_offset(t: ModelTemplate) -> tuple[float, float]:
    """(row, col) of the content box's centre minus the footprint's centre, in pixels."""
    b = content_box(t)
    return (b.r0 + b.r1 - t.height_px) / 2.0, (b.c0 + b.c1 - t.width_px) / 2.0


def _mean_lab(t: ModelTemplate) -> np.ndarray | None:
    if not t.colour_views:
        return None
    v = t.colour_views[0]
    fg = v[..., 3] > 127
    if not fg.any():
        return None
    lab = cv2.cvtColor(np.ascontiguousarray(v[..., :3], np.float32) / 255.0, cv2.COLOR_RGB2Lab)
    return lab[fg].mean(axis=0)


def same_size(a: ModelTemplate, b: ModelTemplate, tol: float) -> bool:
    """Whether the two models' contents (:func:`content_box`) have the same sides within
    ``tol`` (a share of the longer), in either orientation."""
    def close(x: float, y: float) -> bool:
        return abs(x - y) <= tol * max(x, y)

    ba, bb = content_box(a), content_box(b)
    ha, wa, hb, wb = ba.height, ba.width, bb.height, bb.width
    return (close(ha, hb) and close(wa, wb)) or (close(ha, wb) and close(wa, hb))


def depth_similarity(a: ModelTemplate, b: ModelTemplate, pad_px: int = 4) -> float:
    """Best NCC over quarter turns of ``b``'s depth model with ``a``'s, each cropped to its
    content (:func:`content_box`, ``b``'s resampled to ``a``'s), both padded with wall;
    1 when neither has depth, 0 when only one has."""
    da, db = a.depth_filled(), b.depth_filled()
    if da is None and db is None:
        return 1.0
    if da is None or db is None:
        return 0.0
    ba, bb = content_box(a), content_box(b)
    da = np.ascontiguousarray(da[ba.r0:ba.r1, ba.c0:ba.c1])
    db = np.ascontiguousarray(db[bb.r0:bb.r1, bb.c0:bb.c1])
    best = -1.0
    ta = padded_template(da, pad_px)
    for k in range(4):
        r = np.rot90(db, k)
        r = cv2.resize(np.ascontiguousarray(r), (da.shape[1], da.shape[0]), interpolation=cv2.INTER_AREA)
        best = max(best, float(ncc_map(ta, padded_template(r, pad_px))[0, 0]))
    return best


def _has_relief(t: ModelTemplate) -> bool:
    """Whether a model's relief varies inside its content (:func:`relief_score` can compare it)."""
    d = t.depth_filled()
    if d is None:
        return False
    b = content_box(t)
    m = d[b.r0:b.r1, b.c0:b.c1] if d.shape[:2] == (t.height_px, t.width_px) else d
    return m.size > 0 and float(m.std()) >= _FLAT_M * max(float(np.abs(m).max()), 1e-9)


def learnt_view_count(t: ModelTemplate) -> int:
    """How many of a model's last front views are learnt designs (``model.json``
    ``learnt_views``, written by ``sbsc learn``); 0 when it gives none or no whole number."""
    k = t.extra.get("learnt_views", 0)
    return k if isinstance(k, int) and not isinstance(k, bool) and k > 0 else 0


def design_templates(t: ModelTemplate) -> list[ModelTemplate]:
    """A class's model and each of its learnt designs (``model.json`` ``learnt_views``: the
    last so many front views, written by ``sbsc learn``) as a model of its own: that view,
    and the further depth model of the same rank from the end (else the reference one)."""
    k = learnt_view_count(t)
    if k <= 0 or len(t.colour_views) <= 1:
        return [t]
    k = min(k, len(t.colour_views) - 1)
    out = [replace(t, colour_views=t.colour_views[:-k], extra_depths=[])]
    for j, view in enumerate(t.colour_views[-k:]):
        back = k - j  # 1 for the last view
        depth = t.extra_depths[-back] if back <= len(t.extra_depths) else t.depth
        out.append(replace(t, colour_views=[view], depth=depth, extra_depths=[]))
    return out


def lookalike_sets(templates: dict[str, ModelTemplate], settings: LookalikeSettings) -> list[frozenset[str]]:
    """The groups (two or more classes) of look-alike classes of the library."""
    ids = sorted(templates)
    parent = {c: c for c in ids}

    def root(c: str) -> str:
        while parent[c] != c:
            c = parent[c]
        return c

    designs = {c: design_templates(templates[c]) for c in ids}
    labs = {c: [_mean_lab(t) for t in designs[c]] for c in ids}
    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            for (ta, la), (tb, lb) in ((x, y) for x in zip(designs[a], labs[a], strict=True)
                                       for y in zip(designs[b], labs[b], strict=True)):
                if la is None or lb is None or not same_size(ta, tb, settings.size_tolerance):
                    continue
                same_colour = float(np.linalg.norm(la - lb)) <= settings.max_colour_delta_e
                if not same_colour and not settings.depth_alike_any_colour:
                    continue
                if (same_colour and settings.relief_decides and _has_relief(ta) and _has_relief(tb)) or \
                        depth_similarity(ta, tb) >= settings.min_depth_ncc:
                    parent[root(b)] = root(a)
                    break
    groups: dict[str, set[str]] = {}
    for c in ids:
        groups.setdefault(root(c), set()).add(c)
    return sorted((frozenset(g) for g in groups.values() if len(g) > 1), key=sorted)


def print_score(diff: np.ndarray, view: np.ndarray, centre: tuple[float, float], rotation_deg: float,
                *, search_px: int) -> float:
    """Best NCC of a class's front view (Lab difference, (h, w, 3)) turned by ``rotation_deg``
    and its quarter turns, with the scene's Lab difference ``diff`` around ``centre``."""
    best = -1.0
    for k in range(4):
        v = rotate_template(view, float(rotation_deg) + 90.0 * k)
        h, w = v.shape[:2]
        b = box_at(centre, h, w)
        region = crop_padded(diff, b.r0 - search_px, b.r1 + search_px, b.c0 - search_px, b.c1 + search_px)
        if float(np.abs(v).sum()) <= 0 or float(np.abs(region).sum()) <= 0:
            continue
        best = max(best, float(ncc_map(np.ascontiguousarray(region, np.float32),
                                       np.ascontiguousarray(v, np.float32)).max()))
    return best


def relief_score(relief: np.ndarray, model: np.ndarray, centre: tuple[float, float], rotation_deg: float,
                 *, search_px: int) -> float | None:
    """How well a class's depth model (cropped to its content, (h, w) metres) turned by
    ``rotation_deg`` or a quarter turn more explains the relief above the wall ``relief``
    around ``centre``, within the footprint only (the plate's step to the wall says nothing
    about which plate it is); None when the model is flat inside its content (a sign).

    The score is the best NCC less the amplitude misfit there: depth is metric, so a
    relief ``g`` times the model's (least squares) costs ``1 - min(g, 1/g)`` (a flush
    socket is not a 5 cm smoke detector however alike their outlines correlate).
    """
    m = np.asarray(model, np.float32)
    if m.size == 0 or float(m.std()) < _FLAT_M * max(float(np.abs(m).max()), 1e-9):
        return None
    best = -np.inf
    for k in range(4):
        v = np.ascontiguousarray(rotate_template(m, float(rotation_deg) + 90.0 * k), np.float32)
        h, w = v.shape[:2]
        b = box_at(centre, h, w)
        region = np.ascontiguousarray(crop_padded(relief, b.r0 - search_px, b.r1 + search_px,
                                                  b.c0 - search_px, b.c1 + search_px), np.float32)
        if float(np.ptp(v)) <= 0 or float(np.ptp(region)) <= 0:
            continue
        ncc = ncc_map(region, v)
        r, c = np.unravel_index(int(np.argmax(ncc)), ncc.shape)
        gain = float((region[r:r + h, c:c + w] * v).sum() / max(float((v * v).sum()), 1e-12))
        fit = min(gain, 1.0 / gain) if gain > 0 else 0.0
        best = max(best, float(ncc[r, c]) - (1.0 - fit))
    return None if not np.isfinite(best) else best


_FLAT_M = 0.05  # a depth model varying by less than this share of its height inside its content is flat


def _evidence(cand: Candidate, seen: list[str], diff: np.ndarray, views: dict[str, np.ndarray],
              offsets: dict[str, tuple[float, float]], *, relief: np.ndarray | None,
              models: dict[str, np.ndarray | list[np.ndarray]], model_offsets: dict[str, tuple[float, float]],
              search_px: int, relief_mute: frozenset[str] = frozenset()) -> tuple[dict[str, float] | None, bool]:
    """Each class's evidence at a candidate: the mean of the comparisons available for every
    class of ``seen``: its print NCC (when each has a view on this wall) and its relief score
    (:func:`relief_score`, when ``relief`` is given, each has a relief model and none is in
    ``relief_mute``, :func:`relief_muted`); and whether the relief was compared. None when
    neither is available."""
    parts: list[dict[str, float]] = []
    if all(c in views for c in seen):
        parts.append({c: max(print_score(diff, v, _shifted(cand.centre, offsets.get(c), cand.rotation_deg),
                                         cand.rotation_deg, search_px=search_px) for v in designs(views[c]))
                      for c in seen})
    with_relief = False
    if relief is not None and all(c in models and c not in relief_mute for c in seen):
        reliefs = {c: best_design_relief(relief, models[c], _shifted(cand.centre, model_offsets.get(c), cand.rotation_deg),
                                   cand.rotation_deg, search_px=search_px) for c in seen}
        if all(v is not None for v in reliefs.values()):
            parts.append({c: float(v) for c, v in reliefs.items()})  # type: ignore[arg-type]
            with_relief = True
    if not parts:
        return None, False
    return {c: float(np.mean([p[c] for p in parts])) for c in seen}, with_relief


RELIEF_DECIDES_KEY = "relief_decides"  # model.json: false when the examples showed that the relief cannot tell


def relief_muted(templates: dict[str, ModelTemplate]) -> frozenset[str]:
    """The classes whose fine relief takes no part in look-alike decisions: ``model.json``
    ``relief_decides`` false, written by ``sbsc learn`` when on the class's own examples
    another class of its size explained the relief at least as well as the class's own
    models did (:func:`~sbsc_core.recognition.learning.library.relief_tells`). A library
    without it decides exactly as before."""
    return frozenset(c for c, t in templates.items() if t.extra.get(RELIEF_DECIDES_KEY) is False)


def design_prints(templates: dict[str, ModelTemplate], wall_rgb: np.ndarray, threshold: float,
                  pad_px: int = 0) -> dict[str, list[np.ndarray]]:
    """The front views of the further designs of each class that has some (the last
    ``learnt_views`` of its views, ``model.json``; written by ``sbsc learn``) as seen on a wall
    of colour ``wall_rgb``: the Lab difference to the wall where it exceeds ``threshold``,
    cropped to the model's content like :func:`print_views`. Learnt views are crops of the
    scan, so they are compared as they are (no blur, no noise), with a ring of ``pad_px``
    pixels of the surface (no difference) around them: the examples showed the object alone
    on its surface, and the NCC of a plate of one colour that fills its box is its noise
    (a dark switch plate correlated 0.12 with itself on a light wall, 0.96 with its ring).
    :func:`resolve_on_wall` then gives every class's view the same ring: a ring favours the
    class that has it (alt / standard: the alt one-gang socket's learnt print took the library's
    switches)."""
    out: dict[str, list[np.ndarray]] = {}
    wall = cv2.cvtColor(np.asarray(wall_rgb, np.float32).reshape(1, 1, 3) / 255.0, cv2.COLOR_RGB2Lab).reshape(3)
    for c, t in templates.items():
        k = learnt_view_count(t)
        if k <= 0 or not t.colour_views:
            continue
        b = content_box(t)
        prints = []
        for view in t.colour_views[-k:]:
            if view.shape[:2] != (t.height_px, t.width_px):
                continue
            lab = cv2.cvtColor(np.ascontiguousarray(view[..., :3], np.float32) / 255.0, cv2.COLOR_RGB2Lab)
            diff = lab - wall[None, None, :]
            fg = (np.linalg.norm(diff, axis=2) > threshold) & (view[..., 3] > 127)
            diff = np.where(fg[..., None], diff, 0.0).astype(np.float32)
            prints.append(np.ascontiguousarray(np.pad(diff[b.r0:b.r1, b.c0:b.c1], ((pad_px, pad_px), (pad_px, pad_px), (0, 0)))))
        if prints:
            out[c] = prints
    return out


def best_design_relief(relief: np.ndarray, model: np.ndarray | list[np.ndarray], centre: tuple[float, float],
                 rotation_deg: float, *, search_px: int) -> float | None:
    """:func:`relief_score` of a class's depth model, or the best of its designs' (a list:
    the reference model and the further ones, e.g. learnt by ``sbsc learn``). None when one of
    them is flat inside its content (a sign): the class may be a flat plate, which its relief
    cannot tell from another."""
    scores = [relief_score(relief, m, centre, rotation_deg, search_px=search_px) for m in designs(model)]
    if any(x is None for x in scores):
        return None
    return max(scores)


def resolve_lookalikes(cands: list[Candidate], diff: np.ndarray, views: dict[str, np.ndarray],
                       groups: list[frozenset[str]], settings: LookalikeSettings, *,
                       offsets: dict[str, tuple[float, float]] | None = None,
                       relief: np.ndarray | None = None,
                       models: dict[str, np.ndarray | list[np.ndarray]] | None = None,
                       model_offsets: dict[str, tuple[float, float]] | None = None,
                       gain_range: tuple[float, float] | None = None,
                       relief_mute: frozenset[str] = frozenset()) -> list[Candidate]:
    """Candidates with every look-alike class decided by its print (see the module).

    ``diff`` is the wall's Lab difference to the local wall colour (0 off the foreground);
    ``views`` the upright front view of each class as seen on this wall, ``offsets`` (row,
    col) of each view's centre from its footprint's centre (0 when not given). With
    ``relief`` (the wall's relief above its plane, metres) and ``models`` (each class's depth
    model cropped to its content, :func:`relief_models`, whose centres lie ``model_offsets``
    from the footprints'), the fine relief is compared too (:func:`relief_score`), also
    where the classes show no print on this wall. Candidates of a class outside every group,
    or whose group has fewer than two classes compared here, are kept as they are. Relabelled candidates that then coincide with another of the same
    class and source are folded (:func:`~sbsc_core.recognition.matching.nms`).

    With ``gain_range`` and ``relief``, a look-alike whose depth model stands out much more or
    much less than the scene does at the candidate (:func:`amplitude_compatible`) is not one
    of the classes it may be: the library's depth models and the scan decide that, not the print.

    ``relief_mute``: classes whose fine relief is left out of the comparison (:func:`relief_muted`).
    """
    if not groups or not cands:
        return cands
    group_of: dict[str, set[str]] = {}
    for g in groups:
        for c in g:
            group_of.setdefault(c, set()).update(g)
    out: list[Candidate] = []
    touched = False
    for cand in cands:
        g = group_of.get(cand.class_id)
        seen = sorted(c for c in (g or ()) if c in views or (relief is not None and c in (models or {})))
        if gain_range is not None and relief is not None and len(seen) > 1 and cand.class_id in seen:
            mods = {c: (models or {})[c] for c in seen if c in (models or {})}
            fits = amplitude_compatible(relief, mods, {c: _shifted(cand.centre, (model_offsets or {}).get(c),
                                                                   cand.rotation_deg) for c in mods},
                                        cand.rotation_deg, gain_range)
            seen = [c for c in seen if c == cand.class_id or fits.get(c, True)]
        scores, both = (None, False) if g is None or len(seen) < 2 or cand.class_id not in seen else _evidence(
            cand, seen, diff, views, offsets or {}, relief=relief, models=models or {}, model_offsets=model_offsets or {},
            search_px=settings.search_px, relief_mute=relief_mute)
        if scores is None:
            out.append(cand)
            continue
        own = scores[cand.class_id]
        other, other_score = max(((c, s) for c, s in scores.items() if c != cand.class_id), key=lambda x: x[1])
        margin, least = ((settings.min_margin_relief, settings.min_evidence_relief) if both
                         else (settings.min_margin, settings.min_print_ncc))
        floor = least if both else -np.inf  # with the relief: a class below it is like none of the set
        if other_score > own + margin and other_score >= least:
            out.append(replace(cand, class_id=other, lookalike_margin=other_score - max(own, floor)))
            touched = True
        else:
            out.append(replace(cand, lookalike_margin=own - max(other_score, floor)))
    if not touched:
        return out
    folded: list[Candidate] = []
    for source in sorted({c.source for c in out}):
        same = [c for c in out if c.source == source]
        folded.extend(nms(same, 0.5, higher_is_better=source == "depth"))
    return folded


def print_views(protos: dict, templates: dict[str, ModelTemplate]
                ) -> tuple[dict[str, np.ndarray], dict[str, tuple[float, float]]]:
    """Each class's upright front view as seen on a wall (its
    :class:`~sbsc_core.recognition.colour_recognition.WallPrototype`'s unturned view), cropped to the
    model's content (:func:`content_box`), and the content's offset from the footprint centre."""
    views, offsets = {}, {}
    for c, p in protos.items():
        upright = [v for deg, v in p.views if float(deg) % 360.0 == 0.0]
        if not upright or c not in templates:
            continue
        b = content_box(templates[c])
        v = upright[0]
        if v.shape[:2] != (templates[c].height_px, templates[c].width_px):
            views[c], offsets[c] = v, (0.0, 0.0)
            continue
        views[c] = np.ascontiguousarray(v[b.r0:b.r1, b.c0:b.c1])
        offsets[c] = content_offset(templates[c])
    return views, offsets


def relief_models(templates: dict[str, ModelTemplate]
                  ) -> tuple[dict[str, np.ndarray | list[np.ndarray]], dict[str, tuple[float, float]]]:
    """Each class's depth model cropped to its content (:func:`content_box`), and the
    content's offset from the footprint centre (:func:`content_offset`). A class with further
    depth models (other designs, :meth:`~sbsc_core.recognition.templates.ModelTemplate.depth_models`) has
    the list of all of them, each cropped alike; the best of them speaks for the class."""
    models: dict[str, np.ndarray | list[np.ndarray]] = {}
    offsets = {}
    for c, t in templates.items():
        d = t.depth_filled()
        if d is None:
            continue
        if d.shape[:2] == (t.height_px, t.width_px):
            b = content_box(t)
            d = d[b.r0:b.r1, b.c0:b.c1]
            offsets[c] = content_offset(t)
        else:
            offsets[c] = (0.0, 0.0)
        cut = [np.ascontiguousarray(d, np.float32)]
        for design in design_templates(t)[1:]:  # learnt designs: each cropped to its own content
            m = design.depth_filled()
            if m is not None and m.shape[:2] == (t.height_px, t.width_px):
                b = content_box(design)
                cut.append(np.ascontiguousarray(m[b.r0:b.r1, b.c0:b.c1], np.float32))
        models[c] = cut[0] if len(cut) == 1 else cut
    return models, offsets


def _once(prototypes: ColourPrototypes, key: tuple, make: Callable[[], Any]) -> Any:
    """``make()``, made once per library: cached on ``prototypes`` under ``key``."""
    if key not in prototypes._cache:
        prototypes._cache[key] = make()  # the wall prototypes' cache, shared with them
    return prototypes._cache[key]


def _library_sets(prototypes: ColourPrototypes, settings: LookalikeSettings) -> list[frozenset[str]]:
    """:func:`lookalike_sets` of the library's templates, made once per library (cached on ``prototypes``)."""
    key = ("lookalike_sets", settings.size_tolerance, settings.min_depth_ncc, settings.max_colour_delta_e,
           settings.relief_decides, settings.depth_alike_any_colour)
    return _once(prototypes, key, lambda: lookalike_sets(prototypes.templates, settings))


def _library_pairs(prototypes: ColourPrototypes, settings: LookalikeSettings) -> list[tuple[str, str]]:
    """:func:`same_size_pairs` of the library's templates, made once per library (cached on ``prototypes``)."""
    return _once(prototypes, ("same_size_pairs", settings.size_tolerance),
                 lambda: same_size_pairs(prototypes.templates, settings))


def prepare_library(prototypes: ColourPrototypes, settings: LookalikeSettings) -> ColourPrototypes:
    """``prototypes`` with what every wall's :func:`resolve_on_wall` reads of the library alone
    (the look-alike sets, the same-size pairs, the relief models) made now, in their cache:
    a wall's task that receives them (pickled with it) does not make them again."""
    library_relief_models(prototypes)
    if settings.enabled:
        _library_sets(prototypes, settings)
        if settings.colour_confusable:
            _library_pairs(prototypes, settings)
    return prototypes


def library_relief_models(prototypes: ColourPrototypes
                          ) -> tuple[dict[str, np.ndarray | list[np.ndarray]], dict[str, tuple[float, float]]]:
    """:func:`relief_models` of the library's templates, made once per library (cached on
    ``prototypes``, like the look-alike sets)."""
    return _once(prototypes, ("relief_models",), lambda: relief_models(prototypes.templates))


def same_size_pairs(templates: dict[str, ModelTemplate], settings: LookalikeSettings) -> list[tuple[str, str]]:
    """The pairs of classes whose contents have the same size (:func:`content_box`, ``size_tolerance``)."""
    ids = sorted(templates)
    return [(a, b) for i, a in enumerate(ids) for b in ids[i + 1:]
            if same_size(templates[a], templates[b], settings.size_tolerance)]


def colour_confusable(protos: dict, templates: dict[str, ModelTemplate], settings: LookalikeSettings,
                      mu_c: float, *, pairs: list[tuple[str, str]] | None = None) -> list[frozenset[str]]:
    """Pairs of same-size classes (:func:`same_size_pairs`, or ``pairs`` when given) that the
    colour classifier cannot tell apart on a wall: either's wall prototype (``protos``, class
    -> :class:`~sbsc_core.recognition.colour_recognition.WallPrototype`) lies within ``mu_c`` of the other's."""
    out = []
    for a, b in (same_size_pairs(templates, settings) if pairs is None else pairs):
        if a not in protos or b not in protos:
            continue
        pa, pb = protos[a], protos[b]
        if min(prototype_distance(pa.descriptor, pb), prototype_distance(pb.descriptor, pa)) <= mu_c:
            out.append(frozenset((a, b)))
    return out


def resolve_on_wall(depth: list[Candidate], colour: list[Candidate], image: ColourImage,
                    prototypes: ColourPrototypes, settings: LookalikeSettings, *,
                    relief: np.ndarray | None = None,
                    gain_range: tuple[float, float] | None = None) -> tuple[list[Candidate], list[Candidate]]:
    """:func:`resolve_lookalikes` for one wall's depth and colour candidates.

    The look-alike sets are found once per library (cached on ``prototypes``) and joined by
    the pairs the colour classifier cannot tell apart on this wall (:func:`colour_confusable`,
    with ``settings.colour_confusable``); the views are the classes' front views as seen on
    this wall's colour. ``relief``: the wall's relief above its plane (metres, the
    orthoimage's pixels), for the fine relief comparison; ``gain_range`` (the depth
    recognizer's), for the amplitude check (:func:`amplitude_compatible`).
    """
    if not settings.enabled or not (depth or colour):  # nothing to decide: this wall's prototypes are not needed
        return depth, colour
    groups = list(_library_sets(prototypes, settings))
    protos = prototypes.for_wall(image.wall_rgb, image.threshold, image.noise_rgb)
    if settings.colour_confusable:
        pairs = _library_pairs(prototypes, settings)
        groups += [g for g in colour_confusable(protos, prototypes.templates, settings, prototypes.settings.mu_c,
                                                pairs=pairs) if not any(g <= h for h in groups)]
    if not groups:
        return depth, colour
    views, offsets = print_views(protos, prototypes.templates)
    learnt = design_prints(prototypes.templates, image.wall_rgb, image.threshold, settings.learnt_print_pad_px)
    if learnt:  # every print with the same ring of surface as the learnt ones: no class favoured by it
        pad = settings.learnt_print_pad_px
        views = {c: np.pad(v, ((pad, pad), (pad, pad), (0, 0))) for c, v in views.items()}
    for c, prints in learnt.items():
        if c in views:  # a class's further designs (sbsc learn): the best of its prints speaks for it
            views[c] = [views[c], *prints]  # type: ignore[list-item]
    models, model_offsets = library_relief_models(prototypes)
    diff = np.ascontiguousarray(image.lab - image.background, dtype=np.float32)
    np.copyto(diff, 0.0, where=~image.foreground[..., None])  # in place: most of the image
    kw = {"offsets": offsets, "relief": relief, "models": models, "model_offsets": model_offsets,
          "gain_range": gain_range if settings.amplitude_decides else None,
          "relief_mute": relief_muted(prototypes.templates)}
    return (resolve_lookalikes(depth, diff, views, groups, settings, **kw),
            resolve_lookalikes(colour, diff, views, groups, settings, **kw))
