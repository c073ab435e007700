"""``sbsc learn``: a model library (contract 2) taught by reviewed objects of a detect output.

The result holds every class of the given library, plus what the examples teach:

- **a new class** for each class id that the library does not have: its size is the median of
  the examples' sizes (given, or measured as the relief blob under each click), its front view
  ``colour.png`` and depth model ``depth.npy`` the per-pixel medians of the examples' crops
  (:mod:`~sbsc_core.recognition.learning.crops`); its ``name``, ``ifc_class``, ``predefined_type`` and
  ``mount`` come from ``CLASSES.json`` (default ``IfcBuildingElementProxy``, ``mount`` the kinds
  of surface the examples are on);
- **another design** of a class of the library whose examples do not match its models (an
  example that the detect output did not find as its class, or the examples' median best
  correlation with its depth models below ``min_rho``, or their median colour distance to its
  front views above ``max_colour_delta``): one more front view
  ``colour_<k>.png`` and depth model ``depth_<k>.npy`` (the next free ``k``), which
  recognition tries beside the others (docs/model-library.md). A class whose examples match
  is copied unchanged.

The library is written into a temporary folder beside ``out``, checked by reading it back, and
renamed to ``out``: never half-written.
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from ...errors import InputError
from ...io.atomic import atomic_output_dir
from ...io.detections_model import bad_text
from ...io.models import (
    CLASS_ID_RE,
    COLOUR_FILE_RE,
    EXTRA_DEPTH_RE,
    load_model_library,
    load_object_model,
)
from ...io.safe_json import load_json_file
from ...settings import LookalikeSettings
from ...types import SURFACE_KINDS, ObjectModel
from ..amplitude import EXAMPLE_RELIEF_KEY, relief_amplitude
from ..amplitude import designs as model_designs
from ..amplitude import shifted_centre as shifted
from ..lookalikes import (
    RELIEF_DECIDES_KEY,
    best_design_relief,
    design_templates,
    relief_models,
    same_size,
)
from ..templates import ModelTemplate, make_template, resample_depth
from .crops import footprint, learnt_depth, learnt_view, object_alpha
from .examples import (
    Example,
    cut,
    place,
    read_detect_output,
    read_reviewed,
    relief_blob,
    snap_known,
    trust_snap,
)

DEFAULT_IFC_CLASS = "IfcBuildingElementProxy"
FOUND_RADIUS_M = 0.10  # an example within this of a detection of its class was found (contract 5)
MIN_RHO = 0.75  # an example matches a class's design when its relief correlates this well (mu_d)
MAX_COLOUR_DELTA = 25.0  # ... and its colour is within this mean CIELAB distance of a front view
TEMPLATE_PAD_PX = 4  # wall plane around a depth model (settings: depth.template_pad_px)
MIN_RELIEF_M = 0.002  # a learnt depth model flatter than this is left out (recognition skips it)


@dataclass
class Taught:
    """What ``sbsc learn`` did to one class."""

    class_id: str
    action: str  # "new class", "new design", "matches"
    examples: int
    rho: float | None = None  # median best depth correlation with the library's models
    colour_delta: float | None = None  # median best CIELAB distance to its front views
    files: list[str] = field(default_factory=list)
    relief_decides: bool = True  # False: its relief does not tell its examples from another class's

    def to_dict(self) -> dict:
        return {"class": self.class_id, "action": self.action, "examples": self.examples,
                "rho": self.rho, "colour_delta": self.colour_delta, "files": self.files,
                "relief_decides": self.relief_decides}


# --------------------------------------------------------------------------- CLASSES.json


def read_classes(path: Path | None) -> dict[str, dict]:
    """``CLASSES.json``: class id -> {"name", "ifc_class", "predefined_type"?, "mount"?}."""
    if path is None:
        return {}
    doc = load_json_file(path)
    if not isinstance(doc, dict):
        raise InputError(path, "expected a JSON object: class id -> {name, ifc_class, predefined_type?, mount?}")
    out = {}
    for cid, spec in doc.items():
        where = f"{path}: {cid}"
        if not CLASS_ID_RE.match(cid):
            raise InputError(path, f"class id {cid!r} must be lower case letters, digits and '_'")
        if not isinstance(spec, dict):
            raise InputError(where, "expected an object {name, ifc_class, predefined_type?, mount?}")
        unknown = set(spec) - {"name", "ifc_class", "predefined_type", "mount"}
        if unknown:
            raise InputError(where, f"unknown key {sorted(unknown)[0]!r}")
        for key in ("name", "ifc_class", "predefined_type"):
            val = spec.get(key)
            if val is not None and (not isinstance(val, str) or not val.strip() or bad_text(val)):
                raise InputError(where, f"'{key}' must be a non-empty string")
        if "ifc_class" in spec and not spec["ifc_class"].startswith("Ifc"):
            raise InputError(where, f"'ifc_class' must be an IFC entity name such as IfcOutlet, got {spec['ifc_class']!r}")
        mount = spec.get("mount")
        if mount is not None and (not isinstance(mount, list) or not mount
                                  or any(k not in SURFACE_KINDS for k in mount) or len(set(mount)) != len(mount)):
            raise InputError(where, f"'mount' must be a non-empty list of {', '.join(SURFACE_KINDS)}")
        out[cid] = spec
    return out


# --------------------------------------------------------------------------- scores


def _lab(bgr: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(bgr.astype(np.uint8), cv2.COLOR_BGR2LAB).astype(np.float32) * [100 / 255, 1, 1] - [0, 128, 128]


def colour_delta(crop_bgr: np.ndarray, views_rgba: list[np.ndarray]) -> float | None:
    """The smallest mean CIELAB distance between a crop and a front view (over the view's opaque
    pixels), both at the crop's pixels; None without views."""
    from ..templates import resample_rgba

    best = None
    lab = _lab(crop_bgr)
    for view in views_rgba:
        v = resample_rgba(view, crop_bgr.shape[:2])
        opaque = v[..., 3] > 127
        if not opaque.any():
            continue
        dist = np.linalg.norm(lab - _lab(cv2.cvtColor(v[..., :3], cv2.COLOR_RGB2BGR)), axis=2)[opaque]
        d = float(dist.mean())
        best = d if best is None else min(best, d)
    return best


def found(e: Example, detections: list[dict], radius_m: float = FOUND_RADIUS_M) -> bool:
    """Whether recognition found the example as its class (a detection of its class on its
    surface within ``radius_m``, contract 5's match radius)."""
    return any(d.get("class") == e.class_id and d.get("wall") == e.surface.id
               and math.hypot(float(d["u"]) - e.u, float(d["v"]) - e.v) <= radius_m for d in detections)


def _median(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return round(float(np.median(vals)), 4) if vals else None


# --------------------------------------------------------------------------- learning


def _next_index(class_dir: Path) -> int:
    """The next free ``k`` of ``colour_<k>.png`` and ``depth_<k>.npy`` in a class directory."""
    used = [0]
    for p in class_dir.iterdir():
        for rx in (COLOUR_FILE_RE, EXTRA_DEPTH_RE):
            m = rx.match(p.name)
            if m and m.group(1) is not None:
                used.append(int(m.group(1)))
    return max(used) + 1


def _depth_models(model: ObjectModel, pixel_m: float, pad_px: int = TEMPLATE_PAD_PX) -> list[np.ndarray]:
    """The class's depth models at ``pixel_m`` with a border of wall plane, as recognition
    correlates them (a flat-faced box is its rim)."""
    tpl = make_template(model, pixel_m)
    if tpl.relief_m() < MIN_RELIEF_M:
        return []
    return [np.pad(m, pad_px) for m in tpl.depth_models()]


def _write_design(class_dir: Path, examples: list[Example], k: int | None) -> list[str]:
    """Write the medians of ``examples``' crops as ``colour[_k].png`` and ``depth[_k].npy``."""
    suffix = "" if k is None else f"_{k}"
    files = []
    view = learnt_view([e.colour for e in examples])
    if view is not None:
        surfaces = [e.surface_bgr for e in examples if e.surface_bgr is not None]
        alpha = object_alpha(view, np.median(surfaces, axis=0) if surfaces else None,
                             learnt_depth([e.relief for e in examples]))
        view = np.dstack([view, alpha])  # BGRA: the object's box opaque, the surface around it not
        name = f"colour{suffix}.png"
        if not cv2.imwrite(str(class_dir / name), view):
            raise InputError(class_dir / name, "cannot write")
        files.append(name)
    depth = learnt_depth([e.relief for e in examples])
    if depth is not None and np.nanmax(np.abs(depth)) >= MIN_RELIEF_M:
        name = f"depth{suffix}.npy"
        np.save(class_dir / name, depth.astype(np.float32))
        files.append(name)
    return files


def _count_learnt_view(class_dir: Path, files: list[str]) -> None:
    """Count a learnt design's front view in ``model.json``'s ``learnt_views``: the last so many
    views of the class are designs taught by examples (look-alikes compare them on each wall)."""
    if not any(f.startswith("colour") for f in files):
        return
    path = class_dir / "model.json"
    meta = json.loads(path.read_text(encoding="utf-8"))
    k = meta.get("learnt_views", 0)
    meta["learnt_views"] = (k if isinstance(k, int) and not isinstance(k, bool) and k > 0 else 0) + 1
    path.write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")


def _record_amplitudes(class_dir: Path, examples: list[Example]) -> None:
    """Write how far each example stood out (``model.json`` ``example_relief_m``, metres:
    :func:`~sbsc_core.recognition.amplitude.relief_amplitude` of its relief over the class's
    footprint). Recognition refuses a hit of the class (depth or colour) where the scan stands out
    further than every example did, beyond their spread and the wall's noise
    (:func:`~sbsc_core.recognition.amplitude.as_far_as_examples`)."""
    amps = [a for a in (relief_amplitude(e.relief) for e in examples) if a is not None and a > 0]
    if not amps:
        return
    _set_meta(class_dir, EXAMPLE_RELIEF_KEY, [round(a, 5) for a in amps])


def _set_meta(class_dir: Path, key: str, value: object) -> None:
    """Set one key of a class's ``model.json``."""
    path = class_dir / "model.json"
    meta = json.loads(path.read_text(encoding="utf-8"))
    meta[key] = value
    path.write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")


def relief_tells(cid: str, examples: list[Example], templates: dict[str, ModelTemplate],
                 settings: LookalikeSettings | None = None, *, reference: bool = False) -> bool | None:
    """Whether a class's learnt relief tells its examples from every other class of its size.

    Look-alikes are decided by the print and the fine relief together
    (:mod:`~sbsc_core.recognition.lookalikes`). A learnt depth model is the median of a few
    crops of a scan: on a flat plate (a sign) its "fine relief" is the scan's noise and the
    plate's edge, which another plate's model explains as well or better. The examples are
    instances of the class in this building, so they show it, each left out in turn: at each
    example (its place, upright) the class's models, with its learnt one made from the *other*
    examples (a median fits the crops it was made of, noise included), and every class of the
    same size (any of its designs and any of the class's, as
    :func:`~sbsc_core.recognition.lookalikes.lookalike_sets` compares them) score the relief
    (:func:`~sbsc_core.recognition.lookalikes.relief_score`, the best of each class's designs).
    When another class's median score over the examples reaches the class's own, the relief
    does not tell this class's instances from that one's. No threshold: the class's own
    models against the others', on the class's own examples.

    ``reference``: the learnt relief is the class's reference depth model (a new class), else
    its last further depth model (a new design).

    Returns
    -------
    bool or None
        None when it cannot be told: fewer than two examples, no learnt relief, or no other
        class of its size with a relief.
    """
    settings = settings or LookalikeSettings()
    t = templates[cid]
    if len(examples) < 2 or t.depth is None or (not reference and not t.extra_depths):
        return None
    own_designs = design_templates(t)
    others = [c for c in sorted(templates) if c != cid and any(
        same_size(a, b, settings.size_tolerance) for a in own_designs for b in design_templates(templates[c]))]
    models, offsets = relief_models({c: templates[c] for c in others})
    others = [c for c in others if c in models]
    if not others:
        return None
    scores: dict[str, list[float]] = {c: [] for c in [cid, *others]}
    for i, e in enumerate(examples):
        rest = learnt_depth([x.relief for j, x in enumerate(examples) if j != i])
        if rest is None:
            return None
        rest = resample_depth(rest, t.shape)
        loo = replace(t, depth=rest) if reference else replace(t, extra_depths=[*t.extra_depths[:-1], rest])
        own_models, own_offsets = relief_models({cid: loo})
        if cid not in own_models:
            return None
        s = e.surface
        win = footprint(s.depth().shape, s.frame.height_m, s.pixel_m, u=e.u, v=e.v, width_m=e.width_m,
                        height_m=e.height_m)
        if win is None:
            continue
        r0, c0, r1, c1 = win
        with np.errstate(all="ignore"):
            level = float(np.nanmedian(s.depth()[r0:r1, c0:c1] - e.relief))
        relief = np.nan_to_num(s.depth() - level, nan=0.0)
        centre = ((s.frame.height_m - e.v) / s.pixel_m - 0.5, e.u / s.pixel_m - 0.5)
        for c in scores:
            mods, offs = (own_models, own_offsets) if c == cid else (models, offsets)
            found = [x for m in model_designs(mods[c]) if (x := best_design_relief(
                relief, m, shifted(centre, offs.get(c), 0.0), 0.0, search_px=settings.search_px)) is not None]
            if found:
                scores[c].append(max(found))
    if not scores[cid]:
        return None
    own = float(np.median(scores[cid]))
    return not any(scores[c] and float(np.median(scores[c])) >= own for c in others)


def _new_class_size(label: str, objs: list, surfaces_and_clicks: list) -> tuple[float, float]:
    """The median size of a new class's examples: given (``width_m``, ``height_m``) or measured."""
    sizes = []
    for (lab, obj), (s, u, v, _) in zip(objs, surfaces_and_clicks, strict=True):
        if obj.width_m is not None and obj.height_m is not None:
            sizes.append((obj.width_m, obj.height_m))
            continue
        blob = relief_blob(s.depth(), s.frame.height_m, s.pixel_m, u, v)
        if blob is None:
            raise InputError(lab, "no relief under it to measure a new class's size from "
                                  "(give its width_m and height_m)")
        sizes.append(blob[2:])
    w, h = np.median(np.asarray(sizes, float), axis=0)
    return float(w), float(h)


def learn_library(detect_out: Path, reviewed: Path, models: Path, out: Path, *,
                  classes: Path | None = None, min_rho: float = MIN_RHO,
                  max_colour_delta: float = MAX_COLOUR_DELTA,
                  log: Callable[[str], None] | None = None) -> list[Taught]:
    """Write into ``out`` the library ``models`` plus what the reviewed objects teach.

    Parameters
    ----------
    detect_out
        An ``sbsc detect --out`` folder (``detections.json``, ``orthoimages/``).
    reviewed
        A detections document (contract 4) of the objects a person accepted, relabelled or added.
    models
        The model library (contract 2) the detection used.
    out
        The new library's folder; must not exist, or be empty.
    classes
        ``CLASSES.json``: names, IFC classes and mounts of new classes.
    min_rho, max_colour_delta
        When a known class's examples match its models (see the module).

    Returns
    -------
    list of Taught
        One entry per class that had examples, in class order.
    """
    log = log or (lambda msg: None)
    detect_out, reviewed, models, out = Path(detect_out), Path(reviewed), Path(models), Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise InputError(out, "exists and is not empty (give a new folder for the learnt library)")
    if out.resolve() == models.resolve():
        raise InputError(out, "is the input library (give a new folder)")
    library = load_model_library(models)
    specs = read_classes(classes)
    surfaces = read_detect_output(detect_out)
    objs = read_reviewed(reviewed)
    by_class: dict[str, list] = {}
    for lab, obj in objs:
        by_class.setdefault(obj.class_, []).append((lab, obj))
    for cid in specs:
        if cid in library:
            raise InputError(classes, f"{cid}: the library has this class already (CLASSES.json names new classes)")
        if cid not in by_class:
            raise InputError(classes, f"{cid}: no example of this class in {reviewed.name}")
    pixel_m = next(iter(surfaces.values())).pixel_m
    detections = load_json_file(detect_out / "detections.json", max_bytes=64 << 20)["detections"]
    taught: list[Taught] = []
    used: dict[str, list[Example]] = {}  # every class's examples, as cut
    designs: dict[str, list[Example]] = {}
    new: dict[str, tuple[dict, list[Example]]] = {}
    for cid in sorted(by_class):
        items = by_class[cid]
        placed = [place(lab, obj, surfaces) for lab, obj in items]
        if cid in library:
            m = library[cid]
            tmodels = _depth_models(m, pixel_m)
            examples = []
            for (lab, _), (s, u, v, given) in zip(items, placed, strict=True):
                rho = None
                if tmodels:
                    su, sv, rho = snap_known(s, tmodels, u, v)
                    if not given and trust_snap(s, u, v, su=su, sv=sv, rho=rho, width_m=m.width_m,
                                                height_m=m.height_m, min_rho=min_rho):
                        u, v = su, sv
                examples.append(cut(lab, cid, s, u=u, v=v, width_m=m.width_m, height_m=m.height_m, rho=rho))
            rho = _median([e.rho if e.rho is not None else 0.0 for e in examples]) if tmodels else None
            delta = _median([colour_delta(learnt_view([e.colour]), m.colour_views) for e in examples])
            missed = sum(not found(e, detections) for e in examples)
            matches = missed == 0 and (rho is None or rho >= min_rho) and (delta is None or delta <= max_colour_delta)
            used[cid] = examples
            t = Taught(cid, "matches" if matches else "new design", len(examples), rho,
                       None if delta is None else round(delta, 2))
            if not matches:
                designs[cid] = examples
        else:
            w, h = _new_class_size(items[0][0], items, placed)
            examples = []
            for (lab, _), (s, u, v, given) in zip(items, placed, strict=True):
                if not given:
                    blob = relief_blob(s.depth(), s.frame.height_m, s.pixel_m, u, v)
                    if blob is not None:
                        u, v = blob[0], blob[1]
                examples.append(cut(lab, cid, s, u=u, v=v, width_m=w, height_m=h))
            spec = specs.get(cid, {})
            kinds = {e.surface.kind for e in examples}
            meta = {"name": spec.get("name") or cid.replace("_", " ").capitalize(),
                    "ifc_class": spec.get("ifc_class") or DEFAULT_IFC_CLASS,
                    "predefined_type": spec.get("predefined_type"),
                    "width_m": round(w, 4), "height_m": round(h, 4),
                    "mount": spec.get("mount") or [k for k in SURFACE_KINDS if k in kinds],
                    "learnt_from": len(examples)}
            new[cid] = (meta, examples)
            t = Taught(cid, "new class", len(examples))
        used[cid] = examples
        taught.append(t)
    with atomic_output_dir(out) as tmp:
        for cid in library.class_ids:
            shutil.copytree(Path(models) / cid, tmp / cid)
        for t in taught:
            cdir = tmp / t.class_id
            if t.action == "new design":
                t.files = _write_design(cdir, designs[t.class_id], _next_index(cdir))
                _count_learnt_view(cdir, t.files)
            elif t.action == "new class":
                meta, examples = new[t.class_id]
                cdir.mkdir()
                (cdir / "model.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
                t.files = ["model.json", *_write_design(cdir, examples, None)]
            _record_amplitudes(cdir, used[t.class_id])
            load_object_model(cdir)  # read back: the library reader accepts what was written
        learnt = [t for t in taught if any(f.startswith("depth") for f in t.files)]  # a learnt relief was written
        if learnt:  # whether each learnt relief tells the class's examples from the other classes of its size
            pixel = used[learnt[0].class_id][0].surface.pixel_m
            templates = {c: make_template(load_object_model(tmp / c), pixel) for c in sorted(p.name for p in tmp.iterdir())}
            for t in learnt:
                if relief_tells(t.class_id, used[t.class_id], templates, reference=t.action == "new class") is False:
                    _set_meta(tmp / t.class_id, RELIEF_DECIDES_KEY, False)
                    load_object_model(tmp / t.class_id)
                    t.relief_decides = False
        for t in taught:
            log(f"{t.class_id}: {t.action} from {t.examples} example(s)"
                + (f" (rho {t.rho:.2f})" if t.rho is not None else "")
                + (f" (colour {t.colour_delta:.1f})" if t.colour_delta is not None else "")
                + ("" if t.relief_decides else " (its relief does not tell it from another class of its size)"))
    return taught
