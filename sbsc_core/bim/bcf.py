"""The findings of a Scan-vs-BIM comparison as a BCF 2.1 file (bcf-client).

One topic per missing, displaced or unexpected object, so that the findings open in the
BIM tools facility managers already use. Each topic references the IFC files it selects
in: a missing object the designed element of the as-designed IFC, an unexpected one its
element of the as-is IFC (:class:`AsIs`: the exported file's name and GlobalId seed,
:func:`.export.object_guid`), a displaced one both. It has a viewpoint with a camera in
front of the object, looking at the wall, and a snapshot: the wall's orthoimage crop with
the designed and found positions marked (see :mod:`.report`). The topic types
(``Missing``, ``Displaced``, ``Unexpected``) are the BCF's own extension list
(``extensions.xsd`` in the file); dates carry their time zone (UTC).

An object on a ceiling is seen from below (the camera under it, looking up, the image's up
along the ceiling's ``axis_v``), one on a column from the side of its face (a round column:
along the radius through the object).
"""

from __future__ import annotations

import datetime
import os
import tempfile
import uuid
from dataclasses import dataclass
from pathlib import Path

import bcf.v2.model as mdl
import numpy as np
from bcf.v2.bcfxml import BcfXml
from bcf.v2.visinfo import VisualizationInfoHandler, build_camera_from_vectors, build_components
from xsdata.models.datatype import XmlDateTime

from .compare import Comparison, ComparisonItem
from .export import object_guid, review_status, stable_guid
from .report import finding_snapshot, wall_picture
from .surfaces import surface_normal

AUTHOR = "sbsc"
CAMERA_DISTANCE_M = 1.5
TITLES = {"missing": "Missing", "displaced": "Displaced", "unexpected": "Unexpected"}
STATUSES = ("Open", "Closed")
EXTENSIONS_XSD = "extensions.xsd"


@dataclass(frozen=True)
class AsIs:
    """The as-is IFC the unexpected (and displaced) topics select in: its file name and the
    seed of its GlobalIds (:func:`.export.export_ifc`'s ``file_name`` and ``guid_seed``)."""

    file_name: str
    guid_seed: str


def extensions_xsd(labels: list[str]) -> bytes:
    """The BCF 2.1 extension schema: our topic types, statuses and labels (findings, classes)."""
    def enum(name: str, values: list[str]) -> str:
        items = "".join(f'<xs:enumeration value="{v}"/>' for v in values)
        return (f'<xs:simpleType name="{name}"><xs:restriction base="{name}">{items}'
                "</xs:restriction></xs:simpleType>")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<xs:schema xmlns:xs="http://www.w3.org/2001/XMLSchema"><xs:redefine schemaLocation="markup.xsd">'
            + enum("TopicType", list(TITLES.values())) + enum("TopicStatus", list(STATUSES))
            + enum("TopicLabel", labels) + "</xs:redefine>"
            '<xs:element name="ExtendedTopicType" type="TopicType"/>'
            '<xs:element name="ExtendedTopicStatus" type="TopicStatus"/>'
            '<xs:element name="ExtendedTopicLabel" type="TopicLabel"/></xs:schema>\n').encode()


def _fmt(p: np.ndarray | None) -> str:
    return "-" if p is None else "(" + ", ".join(f"{c:.3f}" for c in p) + ")"


def _normal(comparison: Comparison, item: ComparisonItem) -> np.ndarray | None:
    if item.designed is not None and item.designed.normal is not None:
        return item.designed.normal
    if item.wall in comparison.surfaces:
        p = item.detected_position if item.detection is not None else item.designed_position
        return surface_normal(comparison.surfaces[item.wall], p)
    if item.wall in comparison.walls:
        return comparison.walls[item.wall].normal
    return None


def _up(comparison: Comparison, item: ComparisonItem, direction: np.ndarray) -> np.ndarray:
    """The camera's up: +Z, or looking up or down at a ceiling, the ceiling's ``axis_v``."""
    up = np.array([0.0, 0.0, 1.0])
    if abs(float(np.dot(up, direction))) > 0.95:
        sf = comparison.surfaces.get(item.wall) if item.wall else None
        up = np.asarray(sf.frame.axis_v, float) if sf is not None and sf.kind == "ceiling" else np.array([0.0, 1.0, 0.0])
    up = up - np.dot(up, direction) * direction
    return up / np.linalg.norm(up)


def topic_text(comparison: Comparison, item: ComparisonItem) -> tuple[str, str]:
    """(title, description) of one finding."""
    where = f"wall {item.wall}" if item.wall else "no scanned wall"
    title = f"{TITLES[item.status]} {item.class_id} on {where}"
    lines = [f"Scan-vs-BIM finding: {item.status} {item.class_id}."]
    if item.designed is not None:
        d = item.designed
        lines.append(f"Designed: {d.name or d.guid} (IFC {d.ifc_class}, GUID {d.guid}) at {_fmt(d.position)}"
                     + (f" on design wall {d.wall_name}" if d.wall_name else "") + ".")
    if item.detection is not None:
        det = item.detection
        lines.append(f"Found in the scan: detection {det.get('id')} at {_fmt(item.detected_position)}"
                     f" (alpha {det.get('alpha')}, source {det.get('source')}).")
    if item.status == "displaced":
        lines.append(f"Deviation {item.deviation_m:.3f} m (tolerance {comparison.tolerance_m:.3f} m).")
    elif item.status == "missing":
        lines.append("Not found in the scan within "
                     f"{comparison.max_displacement_m:.2f} m: not built, hidden, or not recognized.")
    else:
        lines.append("Not in the as-designed model within "
                     f"{comparison.max_displacement_m:.2f} m of a designed object of its class.")
    return title, " ".join(lines)


def _asis_guid(item: ComparisonItem, asis: AsIs | None) -> str | None:
    """The GlobalId of the finding's as-is element: only an accepted detection is in the
    as-is IFC (its export keeps accepted objects), a pending one is not yet."""
    det = item.detection
    if asis is None or det is None or not det.get("id") or review_status(det) != "accepted":
        return None
    return object_guid(asis.guid_seed, str(det["id"]))


def _viewpoint(comparison: Comparison, item: ComparisonItem, asis: AsIs | None = None) -> mdl.VisualizationInfo:
    p = item.designed_position if item.designed is not None else item.detected_position
    n = _normal(comparison, item)
    if n is None:
        eye = p + np.array([1.0, 1.0, 1.0]) * CAMERA_DISTANCE_M / np.sqrt(3)
    else:
        eye = p + CAMERA_DISTANCE_M * np.asarray(n, float)
    direction = (p - eye) / np.linalg.norm(p - eye)
    up = _up(comparison, item, direction)
    guids = [g for g in ((item.designed.guid if item.designed is not None else None),
                         _asis_guid(item, asis)) if g]
    if guids:
        components = build_components(*guids)
    else:  # nothing to select (BCF 2.1 forbids an empty Selection)
        components = mdl.Components(visibility=mdl.ComponentVisibility(default_visibility=True))
    return mdl.VisualizationInfo(
        guid=str(uuid.uuid4()),
        components=components,
        perspective_camera=build_camera_from_vectors(list(map(float, eye)), list(map(float, direction)),
                                                     list(map(float, up))),
    )


def build_bcf(comparison: Comparison, image_dir: Path | None = None, project_name: str = "Scan-vs-BIM", *,
              asis: AsIs | None = None, author: str = AUTHOR) -> BcfXml:
    """A BCF 2.1 document with one topic per finding (see the module's description)."""
    doc = BcfXml.create_new(project_name)
    labels = sorted({*TITLES, *(item.class_id for item in comparison.findings)})
    doc.project_info.extension_schema = EXTENSIONS_XSD
    doc.extension_schema = extensions_xsd(labels)
    ifc_name = Path(comparison.design.path).name
    now = XmlDateTime.from_datetime(datetime.datetime.now(datetime.UTC).replace(microsecond=0))
    designed_file = mdl.HeaderFile(filename=ifc_name, ifc_project=comparison.design.project_guid,
                                   is_external=True, reference=ifc_name, date=now)
    asis_file = None if asis is None else mdl.HeaderFile(
        filename=asis.file_name, ifc_project=stable_guid(asis.guid_seed, "project"), is_external=True,
        reference=asis.file_name, date=now)
    pictures: dict[str, tuple[np.ndarray, float]] = {}
    for k, item in enumerate(comparison.findings):
        title, description = topic_text(comparison, item)
        topic = doc.add_topic(title, description, author, topic_type=TITLES[item.status], topic_status="Open")
        topic.topic.labels = [item.status, item.class_id]
        topic.topic.index = k + 1
        topic.topic.creation_date = now
        files = [f for f, used in ((designed_file, item.designed is not None),
                                   (asis_file, _asis_guid(item, asis) is not None)) if f is not None and used]
        topic.header = mdl.Header(file=files or [designed_file])
        handler = VisualizationInfoHandler(_viewpoint(comparison, item, asis))
        snapshot = None
        if item.wall in comparison.walls:
            if item.wall not in pictures:
                pictures[item.wall] = wall_picture(comparison, item.wall, image_dir)
            snapshot = finding_snapshot(comparison, item, image_dir, picture=pictures[item.wall])
        if snapshot:
            handler.snapshot = snapshot
            topic.add_visinfo_handler(handler, snapshot_filename="snapshot.png")
        else:
            topic.add_visinfo_handler(handler)
    return doc


def write_bcf(comparison: Comparison, path: Path, image_dir: Path | None = None, *,
              project_name: str = "Scan-vs-BIM", asis: AsIs | None = None, author: str = AUTHOR) -> None:
    """Write the findings' BCF zip to ``path`` (atomically); see :func:`build_bcf`.

    Parameters
    ----------
    comparison
        What :func:`~sbsc_core.bim.compare.compare` found: one topic per finding.
    path
        The ``.bcf`` file to write.
    image_dir
        The detect output's ``orthoimages`` folder, for each topic's snapshot; None: plain walls.
    project_name
        The BCF project's name.
    asis
        The as-is IFC the topics select their objects in (its file name and GlobalId seed).
    author
        The topics' author.
    """
    path = Path(path)
    doc = build_bcf(comparison, image_dir, project_name, asis=asis, author=author)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.partial-", suffix=".bcf", dir=path.parent)
    os.close(fd)
    try:
        doc.save(Path(tmp))
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
