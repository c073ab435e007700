"""Consensus of depth and colour recognition, and positioning (paper, section 4.4).

For one object class, the candidates {D} (depth) and {C} (colour) fill the Recognition
Coherence Matrix Psi: one row per depth candidate plus a "none" row, one column per
colour candidate plus a "none" column. Each cell is the Recognition Coherence Level alpha
of equation 15:

* (I)   alpha = <B_C u B_D> / <B_CD> when the two footprints intersect: the pixels of
        their union over the pixels of the box enclosing both (1 for identical boxes);
* (II)  alpha = 0 when they do not intersect (or lie on different walls);
* (III) alpha = 0.5 (``exclusive_alpha``) in the "none" row / column: the object was
        found by one recognizer only.

The decision is iterative (paper, Figure 13): the highest cell is a recognized instance;
its row and column are removed, except for an exclusive cell (case III), where only that
cell is set to 0 so the "none" row / column stays available to the other candidates (the
selected candidate's own row or column is removed as well, so one candidate is never
counted twice); this stops when Psi is null or the expected number of instances is
reached. Cells within ``alpha_tolerance`` of the best count as tied (equation 15 moves
by a few hundredths for a one-pixel shift); ties are broken by the kind of evidence and
the recognizers' goodness (below).

The position of an instance is equation 16, c = (rho_D c_D + w_C c_C) / (rho_D + w_C).
rho_C is a distance (lower is better), so its weight is w_C = 1 - rho_C (in [0.8, 1] for
accepted candidates with mu_C = 0.2, comparable with rho_D in [0.75, 1]); an exclusive
detection has the other weight 0, i.e. the candidate's own centre. c_D is the depth match's
centre placed by its relief's sharp edges (``Candidate.position``, :mod:`~sbsc_core.recognition.edge_position`)
when it has one: the correlation's centre leans into an occlusion shadow.

``suppress_conflicts`` adds what the paper leaves to the expected counts: when every class
of the library is searched, one place on a wall holds one object, so of two accepted
instances (of any classes) whose footprints overlap by more than ``suppress_overlap``
(intersection over the smaller footprint) only the better one stays, by alpha, then by
the kind of evidence (with ``prefer_depth``: found in both, then depth only, then colour
only: at equal alpha the geometry, which is metric and shape-specific, contradicts a
colour-only class whose depth model did not match there) and then by goodness.

``consensus_all`` runs the selection of every class at once with that rule built in: the
best cell of any class is taken next and accepted only if its place is free, so an
instance that loses its place to another class does not use up its class's expected
count (the two-step ``consensus`` + ``suppress_conflicts`` can). It is the recommended
entry point for a whole floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..settings import ConsensusSettings
from ..types import Box, Candidate
from .matching import box_at, box_overlap


@dataclass
class ConsensusHit:
    """One recognized instance of a class after consensus (pixel coordinates of its wall)."""

    class_id: str
    wall_id: str
    centre: tuple[float, float]  # (row, col), equation 16
    alpha: float
    rho_depth: float | None
    rho_colour: float | None
    source: str  # "both" | "depth" | "colour"
    depth: Candidate | None = None
    colour: Candidate | None = None
    box: Box | None = None  # the footprint at ``centre``
    rotation_deg: float = 0.0
    confidence: float | None = None  # calibrated probability that class and place are right
    unknown: bool = False  # too weak or ambiguous: reported as class "unknown" for review

    @property
    def goodness(self) -> float:
        """The recognizers' mean goodness: rho_D and 1 - rho_C (each in [0, 1])."""
        w = []
        if self.rho_depth is not None:
            w.append(max(0.0, self.rho_depth))
        if self.rho_colour is not None:
            w.append(max(0.0, 1.0 - self.rho_colour))
        return float(np.mean(w)) if w else 0.0


# At equal alpha, depth evidence (metric, shape-specific) outranks the colour descriptors:
# a colour-only class whose depth model did not match where depth found another class is
# contradicted by the geometry, while a depth-only class is merely not salient in colour.
_SOURCE_PRIORITY = {"both": 2, "depth": 1, "colour": 0}


def _weights(d: Candidate | None, c: Candidate | None) -> np.ndarray:
    """(w_D, w_C) of equation 16: rho_D and 1 - rho_C, 0 for a missing candidate."""
    w_d = 0.0 if d is None else max(0.0, float(d.score))
    w_c = 0.0 if c is None else max(0.0, 1.0 - float(c.score))
    return np.array([w_d, w_c])


def coherence_level(b_c: Box, b_d: Box) -> float:
    """alpha of equation 15, cases I and II, for a colour box ``b_c`` and a depth box ``b_d``."""
    inter = b_c.intersection(b_d)
    if inter <= 0:
        return 0.0
    union = b_c.area + b_d.area - inter
    return float(union / b_c.union_box(b_d).area)


def coherence_matrix(depth: list[Candidate], colour: list[Candidate],
                     settings: ConsensusSettings) -> np.ndarray:
    """Psi: (len(depth) + 1) x (len(colour) + 1); the last row / column is "none" (case III)."""
    psi = np.zeros((len(depth) + 1, len(colour) + 1))
    for i, d in enumerate(depth):
        for j, c in enumerate(colour):
            if d.wall_id == c.wall_id:
                psi[i, j] = coherence_level(c.box, d.box)
    psi[: len(depth), len(colour)] = settings.exclusive_alpha
    psi[len(depth), : len(colour)] = settings.exclusive_alpha
    return psi


def weighted_centre(d: Candidate | None, c: Candidate | None,
                    max_disagreement_px: float | None = None) -> tuple[float, float]:
    """Equation 16: (w_D c_D + w_C c_C) / (w_D + w_C); the plain mean if both weights are 0.

    When the two centres lie more than ``max_disagreement_px`` apart (along rows or
    columns) they do not measure the same point: the colour match was placed on a print
    that differs from the model's (another product's label, only the visible part of a
    sign), while the depth match is metric. The depth centre alone is then the position;
    averaging would put the object between the two, off both. Each centre is good to about
    2 mm (one sigma), so two that measure the same point lie within ~7.5 mm (1.5 pixels of
    5 mm, the default) of each other: on realistic scans every pair further apart had the
    colour centre 10-22 mm off and the depth centre within 3.4 mm.
    """
    pts = [x for x in (d, c) if x is not None]
    if not pts:
        raise ValueError("no candidate")
    if len(pts) == 1:
        p = _placed(pts[0])
        return float(p[0]), float(p[1])
    w = _weights(d, c)
    cd = np.asarray(_placed(d), float) if d is not None else np.zeros(2)
    cc = np.asarray(c.centre, float) if c is not None else np.zeros(2)
    if max_disagreement_px is not None and float(np.abs(cd - cc).max()) > max_disagreement_px:
        return float(cd[0]), float(cd[1])
    if w.sum() <= 0:
        m = np.mean([np.asarray(_placed(x), float) for x in pts], axis=0)
        return float(m[0]), float(m[1])
    m = (w[0] * cd + w[1] * cc) / w.sum()
    return float(m[0]), float(m[1])


def _placed(x: Candidate) -> tuple[float, float]:
    """A candidate's centre for placement: a depth match's sharp-edge position when it has one."""
    return x.position if x.position is not None else x.centre


def make_hit(d: Candidate | None, c: Candidate | None, alpha: float,
             settings: ConsensusSettings | None = None) -> ConsensusHit:
    """A ConsensusHit from a selected cell of Psi."""
    ref = d if d is not None else c
    assert ref is not None
    centre = weighted_centre(d, c, (settings or ConsensusSettings()).max_disagreement_px)
    source = "both" if d is not None and c is not None else ("depth" if d is not None else "colour")
    return ConsensusHit(
        class_id=ref.class_id, wall_id=ref.wall_id, centre=centre, alpha=float(alpha),
        rho_depth=None if d is None else float(d.score),
        rho_colour=None if c is None else float(c.score),
        source=source, depth=d, colour=c,
        box=box_at(centre, ref.box.height, ref.box.width), rotation_deg=hit_rotation(d, c),
    )


def hit_rotation(d: Candidate | None, c: Candidate | None, agree_deg: float = 5.0) -> float:
    """The model's turn at a hit: the depth match's (metric), but when the colour match's turn
    agrees with it modulo 90 degrees (within ``agree_deg``), the quarter turn the colour
    pattern tells (a square relief looks alike at every quarter turn, its print does not)."""
    if d is None:
        return float(c.rotation_deg) if c is not None else 0.0
    if c is None:
        return float(d.rotation_deg)
    a, b = float(d.rotation_deg), float(c.rotation_deg)
    diff = (b - a) % 360.0
    k = int(round(diff / 90.0)) % 4
    if abs(diff - 90.0 * round(diff / 90.0)) <= agree_deg:
        return (a + 90.0 * k) % 360.0
    return a


def _cell_rank(depth: list[Candidate], colour: list[Candidate], i: int, j: int,
               settings: ConsensusSettings) -> float:
    """Tie-break of equal cells: a pair before a depth-only before a colour-only cell (if
    ``prefer_depth``), then by the recognizers' goodness (rho_D, 1 - rho_C)."""
    d = depth[i] if i < len(depth) else None
    c = colour[j] if j < len(colour) else None
    source = "both" if d is not None and c is not None else ("depth" if d is not None else "colour")
    prio = _SOURCE_PRIORITY[source] if settings.prefer_depth else 0
    return 10.0 * prio + float(_weights(d, c).sum())


class _Selection:
    """The iterative selection on one class's Psi (paper, Figure 13)."""

    def __init__(self, depth: list[Candidate], colour: list[Candidate], settings: ConsensusSettings,
                 weak_ids: set[int] | None = None) -> None:
        self.depth, self.colour, self.settings = depth, colour, settings
        self.psi = coherence_matrix(depth, colour, settings)
        nd, nc = len(depth), len(colour)
        self.rank = np.array([[_cell_rank(depth, colour, i, j, settings) for j in range(nc + 1)]
                              for i in range(nd + 1)])
        for i, d in enumerate(depth):  # an outscored depth match confirms no colour candidate
            if weak_ids and id(d) in weak_ids:
                for j in range(nc):
                    if self.psi[i, j] > 0:
                        self.psi[i, j] = settings.exclusive_alpha
                        self.rank[i, j] = _cell_rank(depth, colour, nd, j, settings)

    def best(self) -> tuple[float, float, int, int] | None:
        """(alpha, tie-break rank, row, column) of the best cell, None when Psi is null."""
        best = self.psi.max() if self.psi.size else 0.0
        if not best > self.settings.min_alpha:
            return None
        ties = np.argwhere((self.psi >= best - max(self.settings.alpha_tolerance, 1e-12))
                           & (self.psi > self.settings.min_alpha))
        i, j = max((tuple(int(v) for v in x) for x in ties), key=lambda ij: (self.rank[ij], -ij[0], -ij[1]))
        return float(best), float(self.rank[i, j]), i, j

    def hit(self, i: int, j: int) -> ConsensusHit:
        d = self.depth[i] if i < len(self.depth) else None
        c = self.colour[j] if j < len(self.colour) else None
        return make_hit(d, c, self.psi[i, j], self.settings)

    def take(self, i: int, j: int) -> None:
        """Remove the selected cell's row and column (an exclusive cell: only its candidate)."""
        if i < len(self.depth):  # D_i is used up (also after an exclusive (D_i, none))
            self.psi[i, :] = 0.0
        if j < len(self.colour):
            self.psi[:, j] = 0.0

    def drop(self, i: int, j: int) -> None:
        self.psi[i, j] = 0.0


def consensus(depth: list[Candidate], colour: list[Candidate], expected_count: int | None,
              settings: ConsensusSettings) -> list[ConsensusHit]:
    """The recognized instances of ONE class over all walls (section 4.4, Figure 13).

    ``expected_count`` None means no limit (stop when Psi is null); 0 means none.
    """
    if expected_count is not None and expected_count <= 0:
        return []
    sel = _Selection(depth, colour, settings)
    hits: list[ConsensusHit] = []
    while expected_count is None or len(hits) < expected_count:
        cell = sel.best()
        if cell is None:
            break
        hits.append(sel.hit(cell[2], cell[3]))
        sel.take(cell[2], cell[3])
    return hits


def consensus_all(depth: list[Candidate], colour: list[Candidate], expected: dict[str, int] | None,
                  settings: ConsensusSettings, classes: list[str] | None = None) -> dict[str, list[ConsensusHit]]:
    """Consensus of every class at once, with the cross-class rule built in.

    The same iterative selection as :func:`consensus`, but over the matrices of all classes
    together: the best cell of any class is taken next (alpha, then the tie-break), and it is
    accepted only when its footprint does not overlap an already accepted instance by more
    than ``suppress_overlap`` (then only that cell is dropped). So an instance that loses a
    place to another class does not use up its class's expected count, and its candidates
    stay available. ``expected`` None searches every class without a count limit. Depth
    candidates outscored at their place by another class's (:func:`drop_outscored_depth`)
    do not confirm colour candidates: such a pair counts as the colour candidate alone
    (alpha ``exclusive_alpha``, ranked as colour only). Otherwise the weaker depth match,
    paired with a colour candidate of its class, reaches alpha 1 and beats the better depth
    match (alpha 0.5, depth only), and with an expected count also uses up its class's count.
    """
    weak_ids = {id(depth[k]) for k in outscored_depth(depth, settings)}
    names = sorted({c.class_id for c in depth} | {c.class_id for c in colour} | set(classes or []))
    if expected is not None:
        names = [n for n in names if expected.get(n, 0) > 0]
    sels = {n: _Selection([c for c in depth if c.class_id == n], [c for c in colour if c.class_id == n], settings,
                          weak_ids) for n in names}
    left = {n: (None if expected is None else int(expected[n])) for n in names}
    out: dict[str, list[ConsensusHit]] = {n: [] for n in sorted(set(names) | set(classes or []))}
    kept: list[ConsensusHit] = []
    while True:
        cells = [(sel.best(), n) for n, sel in sels.items() if left[n] is None or left[n] > 0]
        cells = [(c, n) for c, n in cells if c is not None]
        if not cells:
            break
        top = max(c[0][0] for c in cells) - max(settings.alpha_tolerance, 1e-12)
        (alpha, rank, i, j), n = max((c for c in cells if c[0][0] >= top), key=lambda x: (x[0][1], x[0][0], x[1]))
        hit = sels[n].hit(i, j)
        if _conflicts(hit, kept, settings):
            sels[n].drop(i, j)
            continue
        sels[n].take(i, j)
        kept.append(hit)
        out[n].append(hit)
        if left[n] is not None:
            left[n] -= 1
    return out


def outscored_depth(depth: list[Candidate], settings: ConsensusSettings) -> set[int]:
    """Indices of the depth candidates that another class's depth candidate at the same place
    (footprints overlapping by more than ``suppress_overlap``) outscores by at least
    ``depth_outscored_margin`` in rho_D.

    Depth is metric and shape-specific: a socket that correlates 0.98 with the socket model
    and 0.82 with the flush-socket model is a socket. Such a weaker depth match does not
    confirm a colour candidate of its class (see :func:`consensus_all`).
    """
    margin = settings.depth_outscored_margin
    if not np.isfinite(margin):
        return set()
    return {k for k, d in enumerate(depth)
            if any(o.class_id != d.class_id and o.wall_id == d.wall_id and o.score >= d.score + margin
                   and box_overlap(o.box, d.box) > settings.suppress_overlap for o in depth)}


def _conflicts(hit: ConsensusHit, kept: list[ConsensusHit], settings: ConsensusSettings) -> bool:
    return hit.box is not None and any(
        k.wall_id == hit.wall_id and k.box is not None and box_overlap(k.box, hit.box) > settings.suppress_overlap
        for k in kept)


def suppress_conflicts(hits_by_class: dict[str, list[ConsensusHit]],
                       settings: ConsensusSettings) -> dict[str, list[ConsensusHit]]:
    """One place holds one object: of overlapping hits (any classes, same wall) keep the best.

    Hits are taken in order of alpha; among those within ``alpha_tolerance`` of the best,
    (``prefer_depth``) both > depth > colour, then goodness decides. A hit is dropped when
    its footprint overlaps an already kept one by more than ``suppress_overlap`` of the
    smaller footprint.
    """
    left = sorted(((cls, h) for cls, hs in hits_by_class.items() for h in hs),
                  key=lambda ch: (ch[0], ch[1].wall_id, ch[1].centre))
    kept: list[ConsensusHit] = []
    out: dict[str, list[ConsensusHit]] = {cls: [] for cls in hits_by_class}
    tol = max(settings.alpha_tolerance, 1e-12)
    while left:
        top = max(h.alpha for _, h in left) - tol
        k = max((k for k, (_, h) in enumerate(left) if h.alpha >= top),
                key=lambda k: (_hit_rank(left[k][1], settings), left[k][1].alpha, -k))
        cls, h = left.pop(k)
        if not _conflicts(h, kept, settings):
            kept.append(h)
            out[cls].append(h)
    return out


def _hit_rank(h: ConsensusHit, settings: ConsensusSettings) -> float:
    """The tie-break of hits with (nearly) equal alpha, as :func:`_cell_rank` for cells."""
    prio = _SOURCE_PRIORITY.get(h.source, 0) if settings.prefer_depth else 0
    n = (h.rho_depth is not None) + (h.rho_colour is not None)
    return 10.0 * prio + h.goodness * n
