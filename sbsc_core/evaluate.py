"""Compare detections with ground truth: the paper's Table 1 (Adán et al. 2018, section 5).

A detection is a true positive when it is matched to a ground-truth object of the same
class whose centre lies within ``max_distance_m`` (default 0.10 m). Matching is greedy
and one-to-one over all same-class pairs, closest first. Unmatched truth objects are
false negatives, unmatched detections false positives.

Per class (in the model library's order, then other classes alphabetically; the names are
the library's, by default the bundled library's) and in total the
table gives, like Table 1: instances, TP %, FN %, FP % (all over the number of
instances: 10 FP among 116 instances read 8.6 %), the share of true positives with
recognition coherence level alpha > 0.9, and the mean and maximum horizontal (XY
plane) and vertical (|dz|) position errors of the true positives in millimetres.

When the ground truth lists ``distractors`` (wall clutter and furniture that are none of
the classes, contract 5), the table also counts the false positives that fall on one (the
detection's centre inside the distractor's box grown by ``DISTRACTOR_MARGIN_M``) and the
share of distractors, wall clutter and furniture separately, that carry at least one.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError
from .io.atomic import write_json_atomic
from .io.documents import TruthDocument, read_detections, read_truth
from .io.models import read_library_metadata
from .paths import bundled_models_dir
from .types import SURFACE_KINDS

EVALUATION_SCHEMA = "sbsc.evaluation/1"
ALPHA_HIGH = 0.9  # Table 1, sixth column: TPs with alpha above this
DISTRACTOR_MARGIN_M = 0.05  # a false positive this close to a distractor's box falls on it


@dataclass
class Match:
    """A true positive: truth object index, detection id and the position errors (metres)."""

    class_id: str
    truth_index: int
    detection_id: str
    distance_m: float
    horizontal_m: float
    vertical_m: float
    alpha: float


@dataclass
class EvaluationRow:
    """One line of Table 1 (a class, or the total). Percentages are None without instances."""

    class_id: str
    name: str
    instances: int
    tp: int
    fn: int
    fp: int
    tp_pct: float | None
    fn_pct: float | None
    fp_pct: float | None
    tp_alpha_high_pct: float | None  # share of the TPs with alpha > 0.9
    h_mean_mm: float | None
    v_mean_mm: float | None
    h_max_mm: float | None
    v_max_mm: float | None

    def to_dict(self) -> dict:
        d = asdict(self)
        d["class"] = d.pop("class_id")
        return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in d.items()}


@dataclass
class EvaluationTable:
    rows: list[EvaluationRow]
    total: EvaluationRow
    max_distance_m: float
    unknown_class_detections: int = 0  # detections of classes absent from the ground truth
    matches: list[Match] = field(default_factory=list)
    distractors: DistractorFigures | None = None  # when the truth lists distractors
    surfaces: list[EvaluationRow] | None = None  # per surface kind, when the truth gives objects' surfaces

    def to_dict(self) -> dict:
        return {
            **({"distractors": asdict(self.distractors)} if self.distractors is not None else {}),
            **({"surfaces": [r.to_dict() for r in self.surfaces]} if self.surfaces is not None else {}),
            "schema": EVALUATION_SCHEMA,
            "max_distance_m": self.max_distance_m,
            "rows": [r.to_dict() for r in self.rows],
            "total": self.total.to_dict(),
            "unknown_class_detections": self.unknown_class_detections,
            "matches": [{k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(m).items()}
                        for m in self.matches],
        }


@dataclass
class DistractorFigures:
    """False positives on things that are none of the classes (clutter and furniture)."""

    clutter: int  # wall clutter items in the truth
    furniture: int  # furniture pieces in the truth
    fp_on_distractors: int  # false positives whose centre falls on a distractor
    clutter_with_fp: int
    furniture_with_fp: int
    fp_by_kind: dict[str, int] = field(default_factory=dict)

    @property
    def clutter_with_fp_pct(self) -> float | None:
        return _pct(self.clutter_with_fp, self.clutter)

    @property
    def furniture_with_fp_pct(self) -> float | None:
        return _pct(self.furniture_with_fp, self.furniture)


def distractor_box(d: dict) -> dict:
    """A distractor as a box: ``centre``, ``axis_u``, ``axis_v``, ``normal`` and ``size_m``
    (extents along them), ``kind`` and ``furniture``.

    Contract 5 gives a distractor by its footprint (``position`` on the wall plane, ``normal``,
    ``width_m``, ``height_m``, ``depth_m`` out from the wall, optionally ``offset_m`` between
    the wall and its back, ``kind`` ``wall`` or ``furniture``); this project's simulator writes
    the box itself. Either is read; a missing field is a one-line error naming it.
    """
    try:
        if "centre" in d:
            box = {k: d[k] for k in ("centre", "axis_u", "axis_v", "normal", "size_m")}
        else:
            n = np.asarray(d["normal"], float)
            n = n / max(float(np.linalg.norm(n)), 1e-12)
            up = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
            au = np.cross(up, n)
            au /= float(np.linalg.norm(au))
            av = np.cross(n, au)
            depth, offset = float(d.get("depth_m", 0.0)), float(d.get("offset_m", 0.0))
            centre = np.asarray(d["position"], float) + n * (offset + depth / 2.0)
            box = {"centre": centre.tolist(), "axis_u": au.tolist(), "axis_v": av.tolist(), "normal": n.tolist(),
                   "size_m": [float(d["width_m"]), float(d["height_m"]), depth + offset]}
    except KeyError as e:
        raise ValueError(f"distractor {d.get('id', d.get('class', '?'))}: no {e.args[0]!r} field") from None
    furniture = bool(d.get("furniture", d.get("kind") == "furniture"))
    kind = d.get("kind") or ("furniture" if furniture else "wall")
    return {**box, "kind": kind, "furniture": furniture}


def on_distractor(position: np.ndarray, d: dict, margin_m: float = DISTRACTOR_MARGIN_M) -> bool:
    """Whether a point lies in a distractor's box (:func:`distractor_box`) grown by ``margin_m``."""
    rel = np.asarray(position, float) - np.asarray(d["centre"], float)
    axes = np.array([d["axis_u"], d["axis_v"], d["normal"]], float)
    return bool(np.all(np.abs(axes @ rel) <= np.asarray(d["size_m"], float) / 2 + margin_m))


def distractor_figures(false_positives: list[dict], distractors: list[dict]) -> DistractorFigures:
    """Count the false positives (detections) that fall on the ground truth's distractors."""
    distractors = [distractor_box(d) for d in distractors]
    hit = np.zeros(len(distractors), bool)
    on = 0
    by_kind: dict[str, int] = {}
    for det in false_positives:
        inside = [k for k, d in enumerate(distractors) if on_distractor(det["position"], d)]
        if inside:
            on += 1
            hit[inside] = True
            kind = distractors[inside[0]]["kind"]
            by_kind[kind] = by_kind.get(kind, 0) + 1
    furn = np.array([bool(d.get("furniture")) for d in distractors], bool)
    return DistractorFigures(clutter=int((~furn).sum()), furniture=int(furn.sum()), fp_on_distractors=on,
                             clutter_with_fp=int((hit & ~furn).sum()), furniture_with_fp=int((hit & furn).sum()),
                             fp_by_kind=by_kind)


def match_class(truth_xyz: np.ndarray, det_xyz: np.ndarray, max_distance_m: float) -> list[tuple[int, int]]:
    """Greedy one-to-one matching, closest pair first, of two (n, 3) sets of centres.

    Returns (truth index, detection index) pairs whose distance is <= ``max_distance_m``.
    Ties keep the order truth index, then detection index.
    """
    if len(truth_xyz) == 0 or len(det_xyz) == 0:
        return []
    dist = np.linalg.norm(truth_xyz[:, None, :] - det_xyz[None, :, :], axis=2)
    ti, di = np.nonzero(dist <= max_distance_m)
    order = np.lexsort((di, ti, dist[ti, di]))
    used_t: set[int] = set()
    used_d: set[int] = set()
    pairs = []
    for k in order:
        t, d = int(ti[k]), int(di[k])
        if t not in used_t and d not in used_d:
            used_t.add(t)
            used_d.add(d)
            pairs.append((t, d))
    return pairs


def _pct(n: int, of: int) -> float | None:
    return 100.0 * n / of if of else None


def _row(class_id: str, name: str, instances: int, fp: int, matches: list[Match]) -> EvaluationRow:
    tp = len(matches)
    h = np.array([m.horizontal_m for m in matches]) * 1000.0
    v = np.array([m.vertical_m for m in matches]) * 1000.0
    high = sum(m.alpha > ALPHA_HIGH for m in matches)
    return EvaluationRow(
        class_id=class_id, name=name, instances=instances, tp=tp, fn=instances - tp, fp=fp,
        tp_pct=_pct(tp, instances), fn_pct=_pct(instances - tp, instances), fp_pct=_pct(fp, instances),
        tp_alpha_high_pct=_pct(high, tp),
        h_mean_mm=float(h.mean()) if tp else None, v_mean_mm=float(v.mean()) if tp else None,
        h_max_mm=float(h.max()) if tp else None, v_max_mm=float(v.max()) if tp else None,
    )


def evaluate(detections_doc: dict, truth: TruthDocument, max_distance_m: float = 0.10, *,
             library: Mapping[str, Mapping] | None = None) -> EvaluationTable:
    """Table 1 for a detections document (contract 4) against a ground truth (contract 5).

    Parameters
    ----------
    detections_doc, truth
        What is scored against what.
    max_distance_m
        The match radius.
    library
        Class id -> ``model.json`` fields, in the library's order
        (:func:`~sbsc_core.io.models.read_library_metadata`): the rows' order and names.
        Default: the bundled library's.

    Returns
    -------
    EvaluationTable
        One row per class and the total (TP, FP, FN, recall, precision), every match, and
        the figures on distractors and per surface kind when the truth has them.
    """
    meta = read_library_metadata(bundled_models_dir()) if library is None else library
    dets = detections_doc["detections"]
    truth_classes = {o.class_id for o in truth.objects}
    classes = {o.class_id for o in truth.objects} | {d["class"] for d in dets}
    ordered = [c for c in meta if c in classes] + sorted(classes - set(meta))
    rows: list[EvaluationRow] = []
    all_matches: list[Match] = []
    total_fp = 0
    false_positives: list[dict] = []
    for cls in ordered:
        t_idx = [i for i, o in enumerate(truth.objects) if o.class_id == cls]
        d_idx = [j for j, d in enumerate(dets) if d["class"] == cls]
        t_xyz = np.array([truth.objects[i].position for i in t_idx], np.float64).reshape(-1, 3)
        d_xyz = np.array([dets[j]["position"] for j in d_idx], np.float64).reshape(-1, 3)
        matches = []
        pairs = match_class(t_xyz, d_xyz, max_distance_m)
        for a, b in pairs:
            delta = d_xyz[b] - t_xyz[a]
            det = dets[d_idx[b]]
            matches.append(Match(cls, t_idx[a], str(det["id"]), float(np.linalg.norm(delta)),
                                 float(np.hypot(delta[0], delta[1])), float(abs(delta[2])),
                                 float(det["alpha"])))
        matched = {b for _, b in pairs}
        false_positives += [dets[j] for k, j in enumerate(d_idx) if k not in matched]
        fp = len(d_idx) - len(matches)
        total_fp += fp
        name = str(meta[cls].get("name", cls)) if cls in meta else cls
        rows.append(_row(cls, name, len(t_idx), fp, matches))
        all_matches.extend(matches)
    total = _row("TOTAL", "TOTAL", len(truth.objects), total_fp, all_matches)
    unknown = sum(1 for d in dets if d["class"] not in truth_classes)
    figures = None
    if "distractors" in truth.extra:
        figures = distractor_figures(false_positives, list(truth.extra["distractors"]))
    by_surface = None
    if any("surface" in o.extra for o in truth.objects):
        by_surface = surface_rows(truth, all_matches, false_positives)
    return EvaluationTable(rows=rows, total=total, max_distance_m=float(max_distance_m),
                           unknown_class_detections=unknown, matches=all_matches, distractors=figures,
                           surfaces=by_surface)


def surface_rows(truth: TruthDocument, matches: list[Match], false_positives: list[dict]) -> list[EvaluationRow]:
    """One row per surface kind (wall, ceiling, column) present: a truth object's kind is its
    ``surface``, a false positive's its detection's ``surface`` (both default ``wall``)."""
    kind_of = [str(o.extra.get("surface") or "wall") for o in truth.objects]
    rows = []
    for kind in SURFACE_KINDS:
        n = kind_of.count(kind)
        fp = sum(1 for d in false_positives if (d.get("surface") or "wall") == kind)
        if n or fp:
            rows.append(_row(kind, f"on {kind}s", n, fp, [m for m in matches if kind_of[m.truth_index] == kind]))
    return rows


_COLUMNS = (  # header, attribute, width, decimals (one space between columns: 100 wide)
    ("Object", "name", 23, None),
    ("Inst", "instances", 5, 0),
    ("TP%", "tp_pct", 6, 1),
    ("FN%", "fn_pct", 6, 1),
    ("FP%", "fp_pct", 6, 1),
    ("a>.9%", "tp_alpha_high_pct", 6, 1),
    ("dh", "h_mean_mm", 6, 1),
    ("dv", "v_mean_mm", 6, 1),
    ("dh max", "h_max_mm", 6, 1),
    ("dv max", "v_max_mm", 6, 1),
    ("TP", "tp", 4, 0),
    ("FN", "fn", 4, 0),
    ("FP", "fp", 4, 0),
)
_LEGEND = ("Inst: instances in the ground truth; a>.9%: share of the TP with coherence alpha > 0.9;\n"
           "dh, dv (max): mean (max) horizontal, vertical position error of the TP in mm; TP, FN, FP: counts")
TABLE_WIDTH = 100  # the table and its notes fit a terminal this wide


def _cell(value, width: int, decimals: int | None) -> str:
    if decimals is None:
        text = str(value)
        return (text if len(text) <= width else text[:width - 1] + "~").ljust(width)
    if value is None:
        return "-".rjust(width)
    return f"{value:.{decimals}f}".rjust(width)


def format_table(table: EvaluationTable) -> str:
    """Table 1 as fixed-width text, with a header, one line per class and a TOTAL line."""
    header = " ".join(h.ljust(w) if d is None else h.rjust(w) for h, _, w, d in _COLUMNS)
    rule = "-" * len(header)
    lines = [header, rule]
    for row in [*table.rows, None, table.total]:
        if row is None:
            lines.append(rule)
            continue
        lines.append(" ".join(_cell(getattr(row, a), w, d) for _, a, w, d in _COLUMNS))
    lines.append(rule)
    for row in table.surfaces or []:
        lines.append(" ".join(_cell(getattr(row, a), w, d) for _, a, w, d in _COLUMNS))
    if table.surfaces:
        lines.append(rule)
    note = f"match radius {table.max_distance_m * 1000:.0f} mm"
    if table.unknown_class_detections:
        note += f"; {table.unknown_class_detections} detection(s) of classes absent from the ground truth (counted as FP)"
    lines.extend(textwrap.wrap(note, TABLE_WIDTH))
    lines.extend(_LEGEND.splitlines())
    f = table.distractors
    if f is not None:
        pct = lambda v: "-" if v is None else f"{v:.1f} %"  # noqa: E731
        kinds = ", ".join(f"{k} {n}" for k, n in sorted(f.fp_by_kind.items()))
        lines.extend(textwrap.wrap(
            f"false positives on distractors: {f.fp_on_distractors}" + (f" ({kinds})" if kinds else "")
            + f"; clutter items with a FP: {f.clutter_with_fp}/{f.clutter} ({pct(f.clutter_with_fp_pct)})"
            + f"; furniture with a FP: {f.furniture_with_fp}/{f.furniture} ({pct(f.furniture_with_fp_pct)})",
            TABLE_WIDTH))
    return "\n".join(lines)


def evaluate_files(detections: Path, truth: Path, json_out: Path | None = None,
                   max_distance_m: float = 0.10, *, models: Path | None = None) -> str:
    """``sbsc evaluate``: read both files, return the text table, optionally write the JSON.

    Parameters
    ----------
    detections
        A detections document (contract 4).
    truth
        Its ground truth (contract 5).
    json_out
        Where to write the table as JSON (atomically); None: not written.
    max_distance_m
        The match radius, > 0.
    models
        The model library whose order and names the table uses; None: the bundled one.

    Returns
    -------
    str
        The table as text, as ``sbsc evaluate`` prints it.
    """
    if not (max_distance_m > 0):
        raise InputError("--max-distance", f"must be > 0, got {max_distance_m}")
    library = read_library_metadata(models) if models is not None else None
    table = evaluate(read_detections(detections), read_truth(truth), max_distance_m, library=library)
    if json_out is not None:
        write_json_atomic(json_out, table.to_dict())
    return format_table(table)
