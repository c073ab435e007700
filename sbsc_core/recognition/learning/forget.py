"""Undo what ``sbsc learn`` taught a class: a learnt class removed, a class's learnt designs removed.

``sbsc learn`` marks what it wrote (docs/model-library.md):

- a **new class** has ``learnt_from`` (the number of its examples) in its ``model.json``;
- **another design** of a known class is one more front view ``colour_<k>.png`` and depth model
  ``depth_<k>.npy``, with ``k`` above every index the class had; ``learnt_views`` in its
  ``model.json`` counts the learnt views (the last so many).

:func:`learnt_part` tells which of the two a class of a library holds, :func:`forget_learnt`
writes a library without it. The library is written into a temporary folder beside ``out``,
read back and renamed: never half-written.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from ...errors import InputError
from ...io.atomic import atomic_output_dir
from ...io.models import COLOUR_FILE_RE, EXTRA_DEPTH_RE, load_model_library
from ..amplitude import EXAMPLE_RELIEF_KEY

NEW_CLASS = "class"
DESIGNS = "designs"


def _meta(class_dir: Path) -> dict:
    try:
        meta = json.loads((class_dir / "model.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return meta if isinstance(meta, dict) else {}


def _count(value: object) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) and value > 0 else 0


def learnt_design_files(class_dir: Path) -> list[str]:
    """The files of a known class's learnt designs: its last ``learnt_views`` front views and the
    depth models of the same or a higher index (``sbsc learn`` writes them at the next free index)."""
    n = _count(_meta(class_dir).get("learnt_views"))
    if n == 0:
        return []
    views = sorted((int(m.group(1)), p.name) for p in class_dir.iterdir()
                   if (m := COLOUR_FILE_RE.match(p.name)) and m.group(1) is not None)
    if len(views) < n:
        return []
    first = views[-n][0]
    depths = [p.name for p in class_dir.iterdir() if (m := EXTRA_DEPTH_RE.match(p.name)) and int(m.group(1)) >= first]
    return sorted([name for _, name in views[-n:]] + depths)


def learnt_part(class_dir: Path) -> str | None:
    """``"class"`` for a class learnt from examples, ``"designs"`` for a known class with learnt
    designs, None when ``sbsc learn`` taught it nothing."""
    if _count(_meta(class_dir).get("learnt_from")):
        return NEW_CLASS
    return DESIGNS if learnt_design_files(class_dir) else None


def learnt_parts(models: Path) -> dict[str, str]:
    """Class id -> :func:`learnt_part` of every class of ``models`` that holds one."""
    out = {}
    for d in sorted(Path(models).iterdir()):
        if d.is_dir() and (d / "model.json").is_file() and (part := learnt_part(d)) is not None:
            out[d.name] = part
    return out


def forget_learnt(models: Path, out: Path, class_ids: list[str]) -> dict[str, str]:
    """Write into ``out`` the library ``models`` without what was learnt for ``class_ids``.

    A class learnt from examples is left out; a known class loses its learnt designs (and
    ``learnt_views``) and keeps the rest. Returns class id -> ``"class"`` or ``"designs"``.
    Raises :class:`InputError` naming a class that is not in ``models`` or has nothing learnt.
    """
    models, out = Path(models), Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise InputError(out, "exists and is not empty (give a new folder)")
    library = load_model_library(models)
    done: dict[str, str] = {}
    for cid in class_ids:
        if cid not in library:
            raise InputError(models, f"{cid}: no such class in the library")
        part = learnt_part(models / cid)
        if part is None:
            raise InputError(models, f"{cid}: nothing in the library was learnt from examples")
        done[cid] = part
    with atomic_output_dir(out) as tmp:
        for cid in library.class_ids:
            if done.get(cid) == NEW_CLASS:
                continue
            shutil.copytree(models / cid, tmp / cid,
                            ignore=(lambda d, names, c=cid: learnt_design_files(models / c)) if cid in done else None)
            if cid in done:
                meta = _meta(tmp / cid)
                meta.pop("learnt_views", None)
                meta.pop(EXAMPLE_RELIEF_KEY, None)  # what its examples measured goes with them
                (tmp / cid / "model.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
        if not any(tmp.iterdir()):
            raise InputError(models, "the library would be empty")
        load_model_library(tmp)  # read back: the library reader accepts what was written
    return done
