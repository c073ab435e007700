"""A calibrated ``confidence`` per detection and an honest "none of these" (issue 13, items 3, 4).

``confidence`` is the probability that a detection is an object of its class at that place
(contract 4). It is a logistic regression on what recognition measured (:func:`hit_features`):
which recognizers found the object, rho_D, 1 - rho_C, alpha (equation 15), the class
margin (how much better the hit's class matched there than any other class), the
look-alike margin (how much better its print matched than the other look-alikes'), the
depth match's own misfit (relief amplitude and extent), how much better its relief fits
than another class's there, and, for a hit seen in colour only, how far its class's model
stands out and how clearly its print names its class. The
coefficients are fitted on the project's own simulated scenes by
``benchmarks/bench_confidence.py`` and ship as ``sbsc_core/recognition/calibration/confidence.json``.

A hit whose confidence is below ``min_confidence`` is weak, ambiguous between classes or
like no class well enough: by default it gives no detection; with ``report_unknown`` it
gives a detection of class ``unknown`` for review (its footprint is the best class's).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..settings import ConfidenceSettings, ConsensusSettings
from ..types import Box, Candidate, WallFrame
from .consensus import ConsensusHit, consensus_all
from .duplicates import cross_surface_duplicates
from .matching import box_overlap
from .templates import ModelTemplate

UNKNOWN_CLASS = "unknown"

CALIBRATION_PATH = Path(__file__).with_name("calibration") / "confidence.json"
FEATURES = ("in_depth", "in_colour", "rho_depth", "colour_goodness", "alpha", "class_margin",
            "lookalike_margin", "gain_misfit", "relief_misfit", "unmatched_relief", "relief_margin",
            "colour_only_print", "gain_excess", "face_deficit", "face_excess", "face_shortfall",
            "relief_surplus")
_MARGIN_CAP = 0.3  # margins beyond this say nothing more
_GAIN_CAP = 1.0  # |ln gain| beyond this (a relief e times too deep or too flat) says nothing more
_RELIEF_CAP_M = 0.02  # a model standing out this far would surely have been matched in depth


def hit_features(hit: ConsensusHit, depth: list[Candidate], colour: list[Candidate],
                 reliefs: dict[str, float] | None = None, *,
                 scene_depth: list[Candidate] | None = None) -> np.ndarray:
    """The features (:data:`FEATURES`) of one consensus hit among all the candidates of its wall.

    ``class_margin``: the hit's rho_D minus the best rho_D of another class at its place
    (footprints overlapping by more than a quarter), or, without depth, the best other
    class's rho_C minus the hit's; capped to [0, 0.3] (0.3 when no other class is there).

    The depth match's own residual tells an object of another size or depth that happens to
    correlate well (a thermostat or a room controller taken for a switch: a plate of nearly
    the switch's outline, twice as deep): ``gain_misfit`` is |ln gain|, the least-squares
    relief amplitude of the scene over the model's (depth is metric: 0 for the right
    object), capped to 1; ``relief_misfit`` is 1 minus the IoU of where the scene and the
    model stand out in the footprint and the wall around it (relief outside the footprint:
    a bigger object; missing inside: a smaller one). Both are 0 without a depth match.

    ``unmatched_relief``: for a hit found in colour only, how far its class's depth model
    stands out (``reliefs``: metres per class), as a share of 2 cm (capped to 1): a flat
    sign is often missed in depth on a noisy scan, a 12 mm switch plate is not, so a
    colour-only switch is more likely something else of its colour. 0 with a depth match
    or without ``reliefs``.

    ``relief_margin``: how much better the hit's depth model covers where the scene stands
    out than another class's depth model at its place: the hit's relief IoU minus the best
    rival's, capped to [0, 0.3] (0.3 when no rival has one). Two classes of about the same
    outline can correlate alike (a square call point and a round smoke detector seen through
    mixed pixels), while only the right one stands out where the scene does. 0 without a
    depth match.

    ``gain_excess``: ``gain_misfit`` where the scene stands out further than the model (ln
    gain > 0), 0 where it stands out less. A scanner flattens relief (mixed pixels at
    edges, range noise averaged over a pixel, rays that miss a recess), it never deepens
    it: a right object's relief comes out at most as deep as its model, while a thermostat
    taken for the flat switch of its outline stands out further. Fitted on its own weight,
    the flattening (``gain_misfit`` alone) is judged apart from the excess.

    ``face_deficit`` and ``face_excess``: how much less, or further, the object's face
    stands out than its model's inside the footprint, away from the outline
    (:func:`~sbsc_core.recognition.depth_recognition.face_gain`): the negative and positive
    parts of its ln, capped to 1 (0 without a depth match). ``gain`` is read mostly on the
    wall ring around the footprint, where a scan's mixed pixels widen a deep object's relief:
    a right 12 cm panel comes out at half its model's depth there, a 4 cm call point at 0.9,
    so ``gain_misfit`` cannot tell the flattening every deep object shows from a flatter
    object of the same outline (a thermostat on a call point's model). Its face can: a right
    object's stands out as far as its model's, whatever its depth.

    ``face_shortfall``: ``face_deficit`` times how far the class's model stands out
    (``reliefs``), as a share of 2 cm (capped to 1). A scan measures a few millimetres of
    relief no better than its noise: a right 2 mm built-in socket comes out a third short
    as often as not, while a thermostat on a 3 cm call point's model, a third short, is
    1 cm missing. 0 without ``reliefs``.

    ``relief_surplus``: for a hit found in colour only, how much further the scene stands
    out at its place than its class's model, as a share of 2 cm (capped to [0, 1]): the
    deepest depth match of another class there (footprints overlapping by more than a
    quarter, among ``scene_depth``, all the scene's depth candidates, when given, since a
    refused hit's candidates are cleared from ``depth``), at its measured relief (its
    model's relief times its face gain, or its gain). A flat print matched where a 2 cm
    object stands out is that object's print, not the flat class's. 0 with a depth match.

    ``colour_only_print``: the look-alike margin again, for a hit found in colour only (0
    otherwise), times 1 - ``unmatched_relief``. Found in colour alone, the print is the only
    evidence of which class it is: a flat sign lost in a noisy scan's depth whose pictogram
    matches its class clearly is likely right, one whose pictogram matches another
    look-alike as well is likely not. A class that stands out should have been matched in
    depth too, so its print alone vouches for less. With depth the relief tells more than
    the print does, so the two get weights of their own.
    """
    here = hit.box

    def others(cands: list[Candidate]) -> list[Candidate]:
        return [c for c in cands if c.wall_id == hit.wall_id and c.class_id != hit.class_id
                and here is not None and box_overlap(c.box, here) > 0.25]

    relief_margin = 0.0
    if hit.rho_depth is not None:
        rivals = others(depth)
        margin = hit.rho_depth - max(c.score for c in rivals) if rivals else _MARGIN_CAP
        ious = [c.relief_iou for c in rivals if c.relief_iou is not None]
        own = None if hit.depth is None else hit.depth.relief_iou
        if own is not None:
            relief_margin = float(np.clip(own - max(ious), 0.0, _MARGIN_CAP)) if ious else _MARGIN_CAP
    else:
        rivals = others(colour)
        margin = min(c.score for c in rivals) - float(hit.rho_colour or 0.0) if rivals else _MARGIN_CAP
    looks = [c.lookalike_margin for c in (hit.depth, hit.colour) if c is not None and c.lookalike_margin is not None]
    look = float(np.clip(min(looks) if looks else _MARGIN_CAP, -_MARGIN_CAP, _MARGIN_CAP))
    d = hit.depth
    ln_gain = 0.0 if d is None or d.gain is None else float(np.clip(np.log(max(d.gain, 1e-6)), -_GAIN_CAP, _GAIN_CAP))
    gain = abs(ln_gain)
    relief = 0.0 if d is None or d.relief_iou is None else float(np.clip(1.0 - d.relief_iou, 0.0, 1.0))
    # how far the hit's class's model stands out, as a share of 2 cm (0 without reliefs)
    stands_out = min(1.0, float(reliefs.get(hit.class_id, 0.0)) / _RELIEF_CAP_M) if reliefs else 0.0
    unmatched = stands_out if d is None else 0.0
    colour_only_print = look * (1.0 - unmatched) if d is None and hit.rho_colour is not None else 0.0
    face = getattr(d, "face_gain", None)  # candidates kept before it was measured have none
    ln_face = 0.0 if face is None else float(np.clip(np.log(max(face, 1e-6)), -_GAIN_CAP, _GAIN_CAP))
    return np.array([
        float(hit.rho_depth is not None), float(hit.rho_colour is not None),
        float(hit.rho_depth or 0.0), 0.0 if hit.rho_colour is None else 1.0 - float(hit.rho_colour),
        float(hit.alpha), float(np.clip(margin, 0.0, _MARGIN_CAP)), look,
        gain, relief, unmatched, relief_margin, colour_only_print, max(ln_gain, 0.0),
        max(-ln_face, 0.0), max(ln_face, 0.0),
        max(-ln_face, 0.0) * stands_out,
        _relief_surplus(hit, others(depth if scene_depth is None else scene_depth), reliefs) if d is None else 0.0,
    ])


def _relief_surplus(hit: ConsensusHit, rivals: list[Candidate], reliefs: dict[str, float] | None) -> float:
    """How much further the scene stands out at a colour-only hit's place than its class's
    model, as a share of 2 cm (capped to [0, 1]): the deepest depth match of another class
    there, at its measured amplitude (its model's relief times its face gain, or its gain)."""
    if not reliefs or not rivals:
        return 0.0
    seen = max(float(reliefs.get(c.class_id, 0.0)) * float(getattr(c, "face_gain", None) or c.gain or 1.0)
               for c in rivals)
    return float(np.clip((seen - float(reliefs.get(hit.class_id, 0.0))) / _RELIEF_CAP_M, 0.0, 1.0))


@dataclass
class Calibration:
    """A logistic model: confidence = 1 / (1 + exp(-(intercept + coef . features))).

    ``features`` names the model's inputs, a subset of :data:`FEATURES` (default: the
    first ``len(coef)`` of them, so a calibration fitted before a feature was added still
    loads). :meth:`predict` takes either those columns or all of :data:`FEATURES`.
    ``link`` (scores, confidences), both increasing, replaces the logistic function by the
    piecewise-linear map through those knots (:func:`isotonic_link`), constant beyond them.
    """

    coef: np.ndarray
    intercept: float
    features: tuple[str, ...] | None = None
    info: dict | None = None
    link: tuple[np.ndarray, np.ndarray] | None = None

    def __post_init__(self) -> None:
        self.coef = np.asarray(self.coef, float)
        if self.features is None:
            self.features = FEATURES[: len(self.coef)]
        self.features = tuple(self.features)
        unknown = [f for f in self.features if f not in FEATURES]
        if unknown or len(self.features) != len(self.coef):
            raise ValueError(f"calibration features {list(self.features)} do not fit {list(FEATURES)} "
                             f"and {len(self.coef)} coefficients")
        if self.link is not None:
            zs, ps = (np.asarray(a, float) for a in self.link)
            if zs.ndim != 1 or zs.shape != ps.shape or not len(zs) or np.any(np.diff(zs) <= 0) \
                    or np.any(np.diff(ps) < 0) or ps.min() < 0 or ps.max() > 1:
                raise ValueError("calibration link: scores must increase and confidences in [0, 1] not decrease")
            self.link = (zs, ps)

    def predict(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, float))
        if x.shape[1] != len(self.features):  # every feature given: take the model's own
            x = x[:, [FEATURES.index(f) for f in self.features]]
        z = self.intercept + x @ self.coef
        if self.link is not None:
            return np.interp(z, *self.link)
        return 1.0 / (1.0 + np.exp(-np.clip(z, -40, 40)))

    def to_dict(self) -> dict:
        link = {} if self.link is None else {"link": {"score": [float(v) for v in self.link[0]],  # unrounded:
                                                      "confidence": [float(v) for v in self.link[1]]}}  # steep ramps
        return {"schema": "sbsc.confidence/1", "features": list(self.features),
                "coef": [round(float(c), 6) for c in self.coef], "intercept": round(float(self.intercept), 6),
                **link, **({"info": self.info} if self.info else {})}

    @classmethod
    def from_dict(cls, d: dict) -> Calibration:
        link = d.get("link")
        features = d.get("features")  # none: the first len(coef) of FEATURES
        return cls(np.asarray(d["coef"], float), float(d["intercept"]), None if features is None else tuple(features),
                   d.get("info"),
                   None if link is None else (np.asarray(link["score"], float), np.asarray(link["confidence"], float)))


def load_calibration(path: Path | None = None) -> Calibration | None:
    """The shipped calibration (None when the package has none), or the one at ``path``.

    Raises :class:`~sbsc_core.errors.InputError` naming ``path`` when it is no file or not a
    calibration (docs/formats.md, "Confidence calibration").
    """
    p = Path(path) if path is not None else CALIBRATION_PATH
    if not p.is_file():
        if path is not None:
            raise InputError(p, "no such calibration file")
        return None
    try:
        return Calibration.from_dict(json.loads(p.read_text(encoding="utf-8")))
    except KeyError as e:
        raise InputError(p, f"not a confidence calibration: no field {e}") from e
    except (OSError, UnicodeDecodeError, ValueError, TypeError, AttributeError) as e:
        raise InputError(p, f"not a confidence calibration: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from e


# The sign each feature's coefficient must have: better evidence never lowers the confidence.
MONOTONE = {"rho_depth": 1, "colour_goodness": 1, "alpha": 1, "class_margin": 1, "lookalike_margin": 1,
            "gain_misfit": -1, "relief_misfit": -1, "unmatched_relief": -1, "relief_margin": 1,
            "colour_only_print": 1, "gain_excess": -1, "face_deficit": -1, "face_excess": -1, "face_shortfall": -1, "relief_surplus": -1}


def fit_logistic(x: np.ndarray, y: np.ndarray, l2: float = 1e-2, signs: list[int] | None = None) -> Calibration:
    """Maximum-likelihood logistic regression with a small L2 penalty on the coefficients.

    ``signs`` (one per column: +1, -1 or 0) bounds each coefficient to be >= 0, <= 0 or
    free (e.g. from :data:`MONOTONE`): a few scenes with correlated features must not teach
    that a worse match is more likely right.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    bounds = None
    if signs is not None:
        if len(signs) != x.shape[1]:
            raise ValueError(f"{len(signs)} signs for {x.shape[1]} features")
        bounds = [(None, None)] + [(0.0, None) if k > 0 else (None, 0.0) if k < 0 else (None, None) for k in signs]

    def loss(w: np.ndarray) -> tuple[float, np.ndarray]:
        z = w[0] + x @ w[1:]
        p = 1.0 / (1.0 + np.exp(-np.clip(z, -40, 40)))
        nll = float(np.sum(np.logaddexp(0.0, z) - y * z)) + 0.5 * l2 * float(w[1:] @ w[1:])
        g = np.concatenate([[np.sum(p - y)], x.T @ (p - y) + l2 * w[1:]])
        return nll, g

    from scipy.optimize import minimize  # here: only calibration needs it, not every detection

    res = minimize(loss, np.zeros(x.shape[1] + 1), jac=True, method="L-BFGS-B", bounds=bounds)
    return Calibration(res.x[1:], float(res.x[0]))


def isotonic_relink(calibration: Calibration, x: np.ndarray, y: np.ndarray) -> Calibration:
    """``calibration`` with its score mapped to a probability by the :func:`isotonic_link` of
    its own score on the rows ``x`` (features in the calibration's order) and their truths ``y``,
    instead of the logistic function: the same order of hits, calibrated at the top too."""
    z = calibration.intercept + np.asarray(x, float) @ calibration.coef
    return replace(calibration, link=isotonic_link(z, y))


def isotonic_link(z: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Knots (scores, confidences) of the non-decreasing map from a score to the share of
    right rows: the pool-adjacent-violators fit (``scipy.optimize.isotonic_regression``) of
    ``y`` over the rows sorted by ``z``, with knots at the first and last score of each block
    of equal fitted value (between blocks the map ramps linearly). A block's share is taken as (right + 1) / (rows + 2): a block of right
    rows only says "very likely", not "certain"; the shares are made non-decreasing again
    (weighted by the blocks' rows).

    The logistic function of Platt scaling has one slope for the whole range: where the top
    of a score's range is purer than its middle, it is under-confident there (a bulk accept
    at 0.99 takes few), this is not.
    """
    from scipy.optimize import isotonic_regression  # here: only calibration needs it

    z, y = np.asarray(z, float), np.asarray(y, float)
    order = np.argsort(z, kind="stable")
    zs, ys = z[order], y[order]
    fitted = isotonic_regression(ys).x
    starts = np.r_[0, np.flatnonzero(np.diff(fitted)) + 1]
    ends = np.r_[starts[1:], len(ys)]
    rows = (ends - starts).astype(float)
    share = isotonic_regression((np.add.reduceat(ys, starts) + 1.0) / (rows + 2.0), weights=rows).x
    knots: list[float] = []
    shares: list[float] = []
    for a, b, p in zip(starts, ends, share, strict=True):
        for zk in (zs[a], zs[b - 1]):  # the block's first and last score: a step, with a ramp between blocks
            if knots and zk <= knots[-1]:  # the same score (ties across blocks): the later, higher share
                shares[-1] = max(shares[-1], float(p))
            else:
                knots.append(float(zk))
                shares.append(float(p))
    return np.array(knots), np.array(shares)


def fit_ranking_logistic(x: np.ndarray, y: np.ndarray, groups: list, l2: float = 1e-2,
                         signs: list[int] | None = None, *, link: str = "platt") -> Calibration:
    """A logistic model fitted to order the hits that compete for one class's count, then
    rescaled to a probability.

    With expected counts, :func:`fill_by_confidence` keeps each class's most probable hits:
    what decides is the order of a class's hits in a scene, right before wrong. Fitted to
    every hit alike, the likelihood also weighs hits that compete with nothing (the one
    electrical panel, right however flattened its relief), and a misfit that tells a
    look-alike from the real object (the thermostat taken for the flat switch of its
    outline) gets the weight those hits allow. So:

    1. the weights are fitted to the feature differences of every (right, wrong) pair of
       rows of one group (one class in one scene, one consensus run), both ways round: a
       Bradley-Terry model of which of two hits is the right one;
    2. the score those weights give each row is mapped to a probability by a logistic fit
       of one slope and an intercept on all rows (Platt scaling), so that the confidence is
       calibrated again. The slope is positive: the order of step 1 is kept.

    With ``link="isotonic"``, step 2 is :func:`isotonic_link` of the same score instead.

    ``signs`` bounds the weights as in :func:`fit_logistic`. Groups without a right and a
    wrong row add no pair; with no pair at all this is :func:`fit_logistic`.
    """
    if link not in ("platt", "isotonic"):
        raise ValueError(f"link must be 'platt' or 'isotonic', not {link!r}")
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    members: dict = {}
    for i, g in enumerate(groups):
        members.setdefault(g, ([], []))[int(y[i] > 0.5)].append(i)
    pairs = np.array([(i, j) for wrong, right in members.values() for i in right for j in wrong], int).reshape(-1, 2)
    if not len(pairs):
        return fit_logistic(x, y, l2, signs)
    d = x[pairs[:, 0]] - x[pairs[:, 1]]
    order = fit_logistic(np.concatenate([d, -d]), np.repeat([1.0, 0.0], len(d)), l2, signs)
    if link == "isotonic":
        return isotonic_relink(Calibration(order.coef, 0.0), x, y)
    platt = fit_logistic((x @ order.coef)[:, None], y, 0.0, [1])
    return Calibration(order.coef * platt.coef[0], platt.intercept)


def reliability(p: np.ndarray, y: np.ndarray, bins: int = 10) -> tuple[list[tuple[float, float, int, float, float]], float]:
    """Reliability table ((bin low, bin high, count, mean confidence, accuracy) per non-empty
    bin of equal width) and the expected calibration error (count-weighted |accuracy - confidence|)."""
    p, y = np.asarray(p, float), np.asarray(y, float)
    edges = np.linspace(0.0, 1.0, bins + 1)
    rows, ece = [], 0.0
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        on = (p >= lo) & ((p < hi) if hi < 1.0 else (p <= hi))
        if not on.any():
            continue
        conf, acc = float(p[on].mean()), float(y[on].mean())
        rows.append((float(lo), float(hi), int(on.sum()), conf, acc))
        ece += on.sum() / max(1, len(p)) * abs(acc - conf)
    return rows, float(ece)


def score_hits(hits: list[ConsensusHit], depth: list[Candidate], colour: list[Candidate],
               calibration: Calibration | None, reliefs: dict[str, float] | None = None, *,
               scene_depth: list[Candidate] | None = None) -> list[float | None]:
    """The confidence of every hit (None for all without a calibration); ``reliefs`` and
    ``scene_depth`` as in :func:`hit_features`."""
    if calibration is None or not hits:
        return [None] * len(hits)
    x = np.stack([hit_features(h, depth, colour, reliefs, scene_depth=scene_depth) for h in hits])
    return [float(v) for v in calibration.predict(x)]


def model_reliefs(templates: dict[str, ModelTemplate]) -> dict[str, float]:
    """How far each class's depth model stands out (metres), for :func:`hit_features`."""
    return {cid: t.relief_m() for cid, t in templates.items()}


def screen_hits(hits: list[ConsensusHit], depth: list[Candidate], colour: list[Candidate],
                settings: ConfidenceSettings) -> list[ConsensusHit]:
    """The hits with their ``confidence``; those below ``min_confidence`` are left out, or kept
    as ``unknown`` with ``report_unknown`` (see the module)."""
    if not settings.enabled:
        return hits
    cal = load_calibration(Path(settings.calibration) if settings.calibration else None)
    out = []
    for h, conf in zip(hits, score_hits(hits, depth, colour, cal), strict=True):
        h.confidence = conf
        if conf is not None and conf < settings.min_confidence:
            if not settings.report_unknown:
                continue
            h.unknown = True
        out.append(h)
    return out


def screened_consensus(depth: list[Candidate], colour: list[Candidate], expected: dict[str, int] | None,
                       classes: list[str], *, consensus_settings: ConsensusSettings,
                       settings: ConfidenceSettings,
                       reliefs: dict[str, float] | None = None, max_rounds: int = 50,
                       frames: Mapping[str, tuple[WallFrame, float]] | None = None) -> list[ConsensusHit]:
    """The consensus of every class (:func:`~sbsc_core.recognition.consensus.consensus_all`) with the
    "none of these" rule inside it, in class order.

    A hit below ``min_confidence`` is a place like no class well enough: every candidate
    (of any class) whose footprint overlaps it by more than ``suppress_overlap`` is taken
    out, and the consensus runs again, so that such a place neither uses up its class's
    expected count (a room controller taken for a switch, while a real switch waits) nor
    passes to its next-best class. A candidate of another class that matched there better
    than the refused hit stays (with expected counts, a smoke detector's place may have gone
    to a weak fire-alarm switch while the smoke detectors' count was full of weak hits).
    Rounds go on until no hit is refused (at most ``max_rounds``: with expected counts, a
    class's count may be full of look-alike clutter several times over before its real
    objects, found by depth alone, come up). With expected counts,
    the as-designed model vouches for the objects still missing at the end: the refused
    hits fill their class's count, best confidence first, where their place is free (a
    real object seen in colour only is then kept). The hits still refused come back as
    ``unknown`` with ``report_unknown`` (when no kept hit covers them).
    Without a calibration or with screening off this is the plain consensus. ``reliefs``:
    see :func:`hit_features` (:func:`model_reliefs` of the templates searched).

    With expected counts and ``settings.fill_by_confidence``, each class's count is then
    filled with its most probable hits (:func:`fill_by_confidence`): the counts say how many
    objects of a class there are, the confidence which hits they most likely are. The
    consensus alone fills a count in the order of alpha (equation 15), so a look-alike seen
    in depth and colour (a room controller, alpha 1, rho_D 0.95) goes before a real object
    of the class that the colour recognizer missed (alpha 0.5, rho_D 0.995).

    With ``frames`` (wall id -> frame and pixel size of its orthoimage), a hit that repeats
    a better one on another wall of the same plane
    (:func:`~sbsc_core.recognition.duplicates.cross_surface_duplicates`: two overlapping pieces of one
    wall both see the object) is taken out like a refused hit, so that it neither counts
    twice nor uses up its class's expected count; it is never reported, not even as
    ``unknown``.
    """
    def run(d: list[Candidate], c: list[Candidate]) -> list[ConsensusHit]:
        hits = consensus_all(d, c, expected, consensus_settings, classes)
        return [h for cls in classes for h in hits.get(cls, [])]

    def repeated(hits: list[ConsensusHit]) -> list[ConsensusHit]:
        if not frames:
            return []
        return cross_surface_duplicates(hits, frames, overlap=consensus_settings.suppress_overlap)

    cal = load_calibration(Path(settings.calibration) if settings.calibration else None) if settings.enabled else None
    all_depth, all_colour = depth, colour
    refused: list[ConsensusHit] = []
    for _ in range(max(1, max_rounds)):
        hits = run(depth, colour)
        for h, conf in zip(hits, score_hits(hits, depth, colour, cal, reliefs, scene_depth=all_depth), strict=True):
            h.confidence = conf
        weak = [h for h in hits if h.confidence is not None and h.confidence < settings.min_confidence]
        twice = repeated([h for h in hits if not any(h is w for w in weak)])
        if not weak and not twice:
            break
        refused.extend(weak)
        depth = _clear_of(depth, weak + twice, consensus_settings.suppress_overlap)
        colour = _clear_of(colour, weak + twice, consensus_settings.suppress_overlap)
    hits = [h for h in hits if h.confidence is None or h.confidence >= settings.min_confidence]
    if cal is None:
        return hits
    if expected is not None:  # the as-designed counts vouch for objects still missing: the best refused fill them
        left = {n: int(expected.get(n, 0)) - sum(h.class_id == n for h in hits) for n in classes}
        for h in sorted(refused, key=lambda h: -(h.confidence or 0.0)):
            if left.get(h.class_id, 0) > 0 and not _overlaps(h, hits, consensus_settings.suppress_overlap):
                hits.append(h)
                left[h.class_id] -= 1
        refused = [h for h in refused if not any(h is k for k in hits)]
        if settings.fill_by_confidence:
            free = screened_consensus(all_depth, all_colour, None, classes, consensus_settings=consensus_settings,
                                      settings=replace(settings, report_unknown=False, fill_by_confidence=False),
                                      reliefs=reliefs, max_rounds=max_rounds, frames=frames)
            hits = fill_by_confidence(hits, free, consensus_settings.suppress_overlap)
            hits = [h for cls in classes for h in hits if h.class_id == cls]
    if settings.report_unknown:
        for h in refused:
            if not _overlaps(h, hits, consensus_settings.suppress_overlap):
                h.unknown = True
                hits.append(h)
    return hits


def fill_by_confidence(hits: list[ConsensusHit], pool: list[ConsensusHit], overlap: float) -> list[ConsensusHit]:
    """``hits`` (selected under expected counts) with each class's least probable hits swapped
    for more probable hits of the same class from ``pool`` (the hits found without counts).

    A hit of ``pool`` replaces the least confident kept hit of its class when its confidence
    is higher and its footprint overlaps no kept hit by more than ``overlap`` (a free place);
    the best of ``pool`` are tried first. Each class keeps its number of hits. Hits without a
    confidence are neither swapped out nor in.
    """
    kept = list(hits)
    for cls in sorted({h.class_id for h in kept}):
        spare = sorted((p for p in pool if p.class_id == cls and p.confidence is not None),
                       key=lambda p: -p.confidence)
        for p in spare:
            mine = [h for h in kept if h.class_id == cls and h.confidence is not None]
            if not mine:
                break
            worst = min(mine, key=lambda h: h.confidence)
            if not p.confidence > worst.confidence:
                break
            if _overlaps(p, kept, overlap):  # its place is taken (by this object, or another's)
                continue
            kept = [h for h in kept if h is not worst] + [p]
    return kept


def _overlaps(hit: ConsensusHit, hits: list[ConsensusHit], overlap: float) -> bool:
    """Whether ``hit``'s footprint overlaps one of ``hits`` on its wall by more than ``overlap``."""
    return any(k.wall_id == hit.wall_id and k.box is not None and hit.box is not None
               and box_overlap(k.box, hit.box) > overlap for k in hits)


def _beats(c: Candidate, h: ConsensusHit) -> bool:
    """Whether candidate ``c`` of another class matched better than the refused hit ``h``
    in its own recognizer (rho_D higher; rho_C lower), or found depth where ``h`` had none."""
    if c.class_id == h.class_id:
        return False
    if c.source == "depth":
        return h.rho_depth is None or c.score > h.rho_depth
    return h.rho_colour is not None and c.score < h.rho_colour


def _clear_of(cands: list[Candidate], hits: list[ConsensusHit], overlap: float) -> list[Candidate]:
    """The candidates whose footprint overlaps none of ``hits`` by more than ``overlap``,
    except those of another class that matched there better than the hit (:func:`_beats`:
    the refused hit had only taken the place of a better class whose count was full then)."""
    return [c for c in cands if not any(c.wall_id == h.wall_id and h.box is not None
                                        and box_overlap(c.box, h.box) > overlap and not _beats(c, h)
                                        for h in hits)]


def unexplained_regions(rois: dict[str, list[Box]], hits: list[ConsensusHit], templates: dict[str, ModelTemplate],
                        *, min_overlap: float = 0.1) -> list[ConsensusHit]:
    """``unknown`` hits for the depth RoIs of an object's size that no hit explains (a thermostat,
    a clock: like no class of the library), for review with ``report_unknown``.

    A RoI is of an object's size when its longer side lies between half the smallest and
    the largest model side; it is explained when a hit's footprint covers more than
    ``min_overlap`` of it.
    """
    if not templates:
        return []
    sides = [s for t in templates.values() for s in (t.height_px, t.width_px)]
    lo, hi = 0.5 * min(sides), max(sides)
    out = []
    for wid in sorted(rois):
        for roi in rois[wid]:
            if not lo <= max(roi.height, roi.width) <= hi:
                continue
            if any(h.wall_id == wid and h.box is not None and box_overlap(h.box, roi) > min_overlap for h in hits):
                continue
            out.append(ConsensusHit(class_id=UNKNOWN_CLASS, wall_id=wid, centre=roi.centre, alpha=0.0,
                                    rho_depth=None, rho_colour=None, source="depth", box=roi, unknown=True))
    return out
