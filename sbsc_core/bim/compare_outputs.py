"""``sbsc compare``'s output folder: the comparison, its HTML report, its BCF findings and the
design's expected counts, written together (nothing on error)."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..io.atomic import atomic_output_dir, write_json_atomic
from ..types import ModelLibrary
from .bcf import write_bcf
from .compare import Comparison, compare
from .design import read_as_designed
from .export import load_json, parse_detections_document
from .report import write_report


def compare_to_dir(as_designed: Path, detections: Path, out: Path, tolerance_m: float = 0.10,
                   library: ModelLibrary | None = None) -> Comparison:
    """``sbsc compare``: write ``comparison.json``, ``report.html``, ``findings.bcf`` and
    ``expected.json`` (contract 3, from the design) into ``out``; nothing on error.

    Orthoimages ``orthoimages/<wall>_colour.png`` beside the detections file are used for
    the per-wall pictures when present.
    """
    as_designed, detections, out = Path(as_designed), Path(detections), Path(out)
    if not tolerance_m > 0:
        raise InputError("--tolerance", f"must be > 0, got {tolerance_m}")
    raw = load_json(detections)
    parse_detections_document(raw, str(detections))
    design = read_as_designed(as_designed, library)
    comparison = compare(design, raw, tolerance_m, detections_path=str(detections))
    image_dir = detections.parent / "orthoimages"
    with atomic_output_dir(out) as tmp:
        write_json_atomic(tmp / "comparison.json", comparison.to_dict())
        write_json_atomic(tmp / "expected.json", design.expected_document())
        write_report(comparison, tmp / "report.html", image_dir=image_dir)
        write_bcf(comparison, tmp / "findings.bcf", image_dir=image_dir)
    return comparison
