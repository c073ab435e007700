"""The coordinate reference system (CRS) a scan's coordinates are in, when the file says.

- LAS/LAZ: the OGC WKT VLR (``LASF_Projection`` 2112) or the GeoTIFF keys (``LASF_Projection``
  34735: ``ProjectedCSTypeGeoKey`` 3072, else ``GeographicTypeGeoKey`` 2048 and the vertical
  ``VerticalCSTypeGeoKey`` 4096);
- E57: the root's ``coordinateMetadata`` string (WKT, ``EPSG:NNNN`` or a URN);
- the command line: ``--crs EPSG:NNNN`` or a WKT text.

Only what is needed for IFC georeferencing is kept (an EPSG code where there is one, the
name, the WKT); no projection maths is done here, so no PROJ database is needed.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError

PROJECTED_KEY, GEOGRAPHIC_KEY, VERTICAL_KEY = 3072, 2048, 4096
USER_DEFINED = 32767


@dataclass(frozen=True)
class CRS:
    """A coordinate reference system: ``name`` is ``EPSG:NNNN`` when the code is known."""

    name: str
    epsg: int | None = None
    wkt: str | None = None
    vertical_epsg: int | None = None
    projected: bool = True  # False: geographic (degrees), not usable as a map CRS

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name}
        if self.epsg is not None:
            d["epsg"] = self.epsg
        if self.vertical_epsg is not None:
            d["vertical_epsg"] = self.vertical_epsg
        if self.wkt:
            d["wkt"] = self.wkt
        if not self.projected:
            d["projected"] = False
        return d

    @classmethod
    def from_dict(cls, d: Any, where: str = "crs") -> CRS:
        if isinstance(d, str):
            return parse_crs(d, where)
        if not isinstance(d, dict) or not isinstance(d.get("name"), str) or not d["name"].strip():
            raise InputError(where, "expected {\"name\": ..., \"epsg\"?: N, \"wkt\"?: ...}")
        epsg = d.get("epsg")
        if epsg is not None and (not isinstance(epsg, int) or isinstance(epsg, bool) or epsg <= 0):
            raise InputError(f"{where}.epsg", f"expected a positive integer, got {epsg!r}")
        return cls(name=d["name"].strip(), epsg=epsg, wkt=d.get("wkt") or None,
                   vertical_epsg=d.get("vertical_epsg"), projected=bool(d.get("projected", True)))


_EPSG_TEXT = re.compile(r"^\s*(?:EPSG\s*:\s*|urn:ogc:def:crs:EPSG:[\d.]*:|https?://www\.opengis\.net/def/crs/EPSG/0/)"
                        r"(\d{4,6})\s*$", re.I)
_WKT_NAME = re.compile(r'^\s*(PROJCS|PROJCRS|GEOGCS|GEOGCRS|COMPD_CS|COMPOUNDCRS|GEODCRS|BOUNDCRS)\s*\[\s*"([^"]*)"', re.I)


def _wkt_epsg(wkt: str) -> int | None:
    """The EPSG code of the WKT's outermost CRS (its last AUTHORITY/ID at depth 1)."""
    depth, last = 0, None
    for m in re.finditer(r'[\[\]]|(?:AUTHORITY|ID)\s*\[\s*"EPSG"\s*,\s*"?(\d+)"?', wkt, re.I):
        tok = m.group(0)
        if tok == "[":
            depth += 1
        elif tok == "]":
            depth -= 1
        else:
            if depth == 1:
                last = int(m.group(1))
            depth += 1  # the AUTHORITY's own bracket
    return last


def parse_crs(text: str, where: str = "--crs") -> CRS:
    """``EPSG:25832`` (or an EPSG URN/URL) or a WKT text; else a one-line ``InputError``."""
    text = (text or "").strip()
    m = _EPSG_TEXT.match(text)
    if m:
        return CRS(name=f"EPSG:{int(m.group(1))}", epsg=int(m.group(1)))
    m = _WKT_NAME.match(text)
    if m:
        kind = m.group(1).upper()
        code = _wkt_epsg(text)
        projected = not kind.startswith("GEOG")
        return CRS(name=f"EPSG:{code}" if code else m.group(2), epsg=code, wkt=text, projected=projected)
    raise InputError(where, f"not a coordinate system: {text[:40]!r} (expected EPSG:NNNN or a WKT text)")


def las_crs(path: Path) -> CRS | None:
    """The CRS recorded in a LAS/LAZ file's VLRs, or None."""
    import laspy

    with laspy.open(path) as reader:
        header = reader.header
        vlrs = list(header.vlrs) + list(getattr(header, "evlrs", None) or [])
    for v in vlrs:
        if getattr(v, "record_id", None) == 2112 and getattr(v, "string", ""):
            return parse_crs(v.string, str(path))
    for v in vlrs:
        keys = {k.id: k for k in getattr(v, "geo_keys", []) if getattr(k, "tiff_tag_location", 1) == 0}
        if not keys:
            continue
        vertical = keys[VERTICAL_KEY].value_offset if VERTICAL_KEY in keys else None
        vertical = vertical if vertical and vertical != USER_DEFINED else None
        for key, projected in ((PROJECTED_KEY, True), (GEOGRAPHIC_KEY, False)):
            code = keys[key].value_offset if key in keys else None
            if code and code != USER_DEFINED:
                return CRS(name=f"EPSG:{code}", epsg=int(code), vertical_epsg=vertical, projected=projected)
    return None


def e57_crs(path: Path) -> CRS | None:
    """The CRS of an E57 file's ``coordinateMetadata``, or None when it is empty."""
    import pye57

    e57 = pye57.E57(str(path))
    try:
        root = e57.root
        names = {root[i].elementName() for i in range(root.childCount())}
        text = root["coordinateMetadata"].value() if "coordinateMetadata" in names else ""
    finally:
        e57.close()
    text = (text or "").strip()
    return parse_crs(text, f"{path}: coordinateMetadata") if text else None


def scan_crs(paths: Sequence[Path]) -> CRS | None:
    """The CRS that the scan files record (None if none does); files that disagree are refused."""
    from .scans import crs_reader

    found: list[tuple[Path, CRS]] = []
    for p in map(Path, paths):
        read = crs_reader(p.suffix)
        try:
            crs = read(p) if read is not None else None
        except InputError:
            raise
        except Exception:  # an unreadable header is reported by the scan reader itself
            crs = None
        if crs is not None:
            found.append((p, crs))
    names = {c.name for _, c in found}
    if len(names) > 1:
        (pa, a), (pb, b) = found[0], next(f for f in found if f[1].name != found[0][1].name)
        raise InputError(pb, f"coordinate system {b.name} differs from {a.name} of {pa.name}")
    return found[0][1] if found else None


def georeference_fields(crs: CRS | None, origin: Any) -> dict[str, Any]:
    """Top-level fields of detections.json: ``crs`` (when known) and ``origin``, the point the
    scan was recentred on (world = local + origin), in the scan's coordinates."""
    import numpy as np

    fields: dict[str, Any] = {"origin": [round(float(c), 4) for c in np.asarray(origin, float).reshape(3)]}
    if crs is not None:
        fields["crs"] = crs.to_dict()
    return fields
