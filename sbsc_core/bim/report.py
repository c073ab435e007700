"""Self-contained HTML report of a Scan-vs-BIM comparison, one picture per scanned wall.

Each picture is the wall's colour orthoimage (``orthoimages/<wall>_colour.png`` beside
the detections, row 0 = top of the wall) or, without it, a plain drawing of the wall and
its openings, with the designed and the found positions marked:

- found: green box (detection) with a blue cross at the designed position;
- displaced: blue box (designed), orange box (found), an arrow between them;
- missing: red box with a cross at the designed position;
- unexpected: magenta box at the found position.

Pictures are PNG embedded as base64, so the file can be mailed or attached as it is.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path

import cv2
import numpy as np

from ..types import WallFrame
from .compare import Comparison, ComparisonItem

PX_PER_M_RANGE = (60.0, 220.0)  # picture scale limits
PICTURE_WIDTH_PX = 1100  # target picture width
MIN_MARK_PX = 10  # smallest marker box

# BGR colours
C_DESIGN = (200, 110, 20)
C_FOUND = (40, 170, 40)
C_DISPLACED = (0, 140, 255)
C_MISSING = (40, 40, 220)
C_UNEXPECTED = (200, 40, 200)
STATUS_COLOUR = {"found": C_FOUND, "displaced": C_DISPLACED, "missing": C_MISSING, "unexpected": C_UNEXPECTED,
                 "not_scanned": (128, 128, 128)}


def _scale(frame: WallFrame) -> float:
    lo, hi = PX_PER_M_RANGE
    return float(np.clip(PICTURE_WIDTH_PX / max(frame.width_m, 1e-3), lo, hi))


def load_orthoimage(image_dir: Path | None, wall_id: str) -> np.ndarray | None:
    """``<image_dir>/<wall>_colour.png`` as BGR, None when absent or unreadable."""
    if image_dir is None:
        return None
    p = Path(image_dir) / f"{wall_id}_colour.png"
    if not p.is_file():
        return None
    img = cv2.imread(str(p), cv2.IMREAD_COLOR)
    return img if img is not None and img.size else None


def wall_background(frame: WallFrame, openings: list[dict], ortho: np.ndarray | None) -> tuple[np.ndarray, float]:
    """The picture of a wall before marking, and its scale in pixels per metre."""
    s = _scale(frame)
    size = (max(1, round(frame.width_m * s)), max(1, round(frame.height_m * s)))
    if ortho is not None:
        return cv2.resize(ortho, size, interpolation=cv2.INTER_AREA), s
    img = np.full((size[1], size[0], 3), 236, np.uint8)
    for o in openings:
        p0 = (_px(o["u_min"] * s), _px((frame.height_m - o["v_max"]) * s))
        p1 = (_px(o["u_max"] * s), _px((frame.height_m - o["v_min"]) * s))
        cv2.rectangle(img, p0, p1, (205, 205, 205), -1)
        cv2.rectangle(img, p0, p1, (150, 150, 150), 1)
        cv2.putText(img, str(o.get("kind", "")), (p0[0] + 4, p0[1] + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (110, 110, 110), 1, cv2.LINE_AA)
    cv2.rectangle(img, (0, 0), (size[0] - 1, size[1] - 1), (120, 120, 120), 1)
    return img, s


PX_LIMIT = 1 << 20  # drawing coordinates are clipped to this (OpenCV takes 32-bit ints)


def _px(x: float) -> int:
    """A pixel coordinate for OpenCV: rounded, clipped to +-PX_LIMIT (a far or non-finite
    position is drawn off the picture rather than overflowing)."""
    x = float(x)
    if x != x:  # NaN
        return -PX_LIMIT
    return round(min(max(x, -PX_LIMIT), PX_LIMIT))


def _to_px(frame: WallFrame, s: float, u: float, v: float) -> tuple[int, int]:
    return _px(u * s), _px((frame.height_m - v) * s)


def _box(img: np.ndarray, frame: WallFrame, s: float, u: float, v: float, *, size: tuple[float, float],
         colour: tuple[int, int, int], thickness: int = 2) -> tuple[tuple[int, int], tuple[int, int]]:
    cx, cy = _to_px(frame, s, u, v)
    w, h = size
    hw, hh = max(MIN_MARK_PX / 2, w * s / 2), max(MIN_MARK_PX / 2, h * s / 2)
    hw, hh = min(hw, PX_LIMIT), min(hh, PX_LIMIT)
    p0, p1 = (_px(cx - hw), _px(cy - hh)), (_px(cx + hw), _px(cy + hh))
    cv2.rectangle(img, p0, p1, colour, thickness, cv2.LINE_AA)
    return p0, p1


Rect = tuple[int, int, int, int]  # x0, y0, x1, y1 in pixels


def _overlaps(a: Rect, b: Rect) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


class _Labels:
    """The labels of one picture, placed once every box is drawn: each beside its box where
    it covers no box and no label placed before it (above, below, right, left, then further
    out), so that labels never run into the boxes or into each other."""

    FONT, SCALE = cv2.FONT_HERSHEY_SIMPLEX, 0.42

    def __init__(self) -> None:
        self.boxes: list[Rect] = []
        self.texts: list[tuple[str, Rect, tuple[int, int, int]]] = []

    def box(self, p0: tuple[int, int], p1: tuple[int, int]) -> None:
        self.boxes.append((min(p0[0], p1[0]) - 2, min(p0[1], p1[1]) - 2, max(p0[0], p1[0]) + 2, max(p0[1], p1[1]) + 2))

    def add(self, text: str, p0: tuple[int, int], p1: tuple[int, int], colour: tuple[int, int, int]) -> None:
        self.texts.append((text, (p0[0], p0[1], p1[0], p1[1]), colour))

    def draw(self, img: np.ndarray) -> None:
        h, w = img.shape[:2]
        placed: list[Rect] = []
        for text, (x0, y0, x1, y1), colour in self.texts:
            (tw, th), base = cv2.getTextSize(text, self.FONT, self.SCALE, 1)
            lw, lh = tw + 4, th + base + 4
            cands = []
            for k in range(4):  # rings further and further out
                gap = 2 + k * (lh + 2)
                cands += [(x0, y0 - gap - lh), (x0, y1 + gap), (x1 + gap + k * lw, y0), (x0 - gap - lw - k * lw, y0)]
            rects = [(int(np.clip(x, 0, max(0, w - lw))), int(np.clip(y, 0, max(0, h - lh)))) for x, y in cands]
            rects = [(x, y, x + lw, y + lh) for x, y in rects]
            free = next((r for r in rects if not any(_overlaps(r, b) for b in self.boxes + placed)), rects[0])
            placed.append(free)
            cv2.rectangle(img, free[:2], (free[2] - 1, free[3] - 1), (255, 255, 255), -1)
            cv2.putText(img, text, (free[0] + 2, free[3] - base - 2), self.FONT, self.SCALE, colour, 1, cv2.LINE_AA)


def _uv(frame: WallFrame, p: np.ndarray) -> tuple[float, float]:
    u, v, _ = frame.to_uvd(np.asarray(p, float)[None])[0]
    return float(u), float(v)


def _designed_size(item: ComparisonItem) -> tuple[float, float]:
    d = item.designed
    return (d.width_m or 0.1, d.height_m or 0.1) if d is not None else (0.1, 0.1)


def _detected_size(item: ComparisonItem) -> tuple[float, float]:
    det = item.detection or {}
    return float(det.get("width_m") or 0.1), float(det.get("height_m") or 0.1)


def mark_item(img: np.ndarray, frame: WallFrame, s: float, wall_id: str, item: ComparisonItem,
              *, labels: _Labels | None = None) -> None:
    """Draw one item's designed and/or found position if it lies on ``wall_id``; its label
    goes to ``labels`` (placed by :meth:`_Labels.draw` once every box is there), or is drawn
    at once without it."""
    own = labels is None
    labels = _Labels() if own else labels
    on_design = item.designed is not None and item.design_wall == wall_id
    on_found = item.detection is not None and item.detection_wall == wall_id
    colour = STATUS_COLOUR[item.status]
    if on_design:
        du, dv = _uv(frame, item.designed.position)
        if item.status == "found":
            c = _to_px(frame, s, du, dv)
            cv2.drawMarker(img, c, C_DESIGN, cv2.MARKER_CROSS, 12, 2, cv2.LINE_AA)
        else:
            p0, p1 = _box(img, frame, s, du, dv, size=_designed_size(item),
                          colour=C_DESIGN if item.status == "displaced" else colour)
            labels.box(p0, p1)
            if item.status == "missing":
                cv2.line(img, p0, p1, colour, 2, cv2.LINE_AA)
                cv2.line(img, (p0[0], p1[1]), (p1[0], p0[1]), colour, 2, cv2.LINE_AA)
                labels.add(f"missing {item.class_id}", p0, p1, colour)
    if on_found:
        fu, fv = _uv(frame, item.detected_position)
        p0, p1 = _box(img, frame, s, fu, fv, size=_detected_size(item), colour=colour)
        labels.box(p0, p1)
        if item.status == "unexpected":
            labels.add(f"unexpected {item.detection.get('class')}", p0, p1, colour)
        if item.status == "displaced":
            labels.add(f"{item.class_id} moved {item.deviation_m:.2f} m", p0, p1, colour)
    if on_design and on_found and item.status == "displaced":
        a = _to_px(frame, s, *_uv(frame, item.designed.position))
        b = _to_px(frame, s, *_uv(frame, item.detected_position))
        cv2.arrowedLine(img, a, b, C_DISPLACED, 2, cv2.LINE_AA, tipLength=0.15)
    if own:
        labels.draw(img)


def wall_picture(comparison: Comparison, wall_id: str, image_dir: Path | None = None) -> tuple[np.ndarray, float]:
    """(BGR picture of one scanned wall with every item marked, pixels per metre)."""
    frame = comparison.walls[wall_id]
    openings = [o for o in comparison.openings if o.get("wall") == wall_id]
    img, s = wall_background(frame, openings, load_orthoimage(image_dir, wall_id))
    labels = _Labels()
    for item in comparison.items:
        mark_item(img, frame, s, wall_id, item, labels=labels)
    labels.draw(img)
    return img, s


def finding_snapshot(comparison: Comparison, item: ComparisonItem, image_dir: Path | None = None,
                     half_window_m: float = 1.0,
                     picture: tuple[np.ndarray, float] | None = None) -> bytes | None:
    """A PNG crop of the wall picture around one finding (BCF snapshot), None off-wall.

    ``picture`` is the wall's :func:`wall_picture` when already drawn.
    """
    wid = item.wall
    if wid is None or wid not in comparison.walls:
        return None
    img, s = picture if picture is not None else wall_picture(comparison, wid, image_dir)
    frame = comparison.walls[wid]
    p = item.designed_position if item.designed is not None and item.design_wall == wid else item.detected_position
    cx, cy = _to_px(frame, s, *_uv(frame, p))
    r = _px(half_window_m * s)
    crop = img[max(0, cy - r):cy + r, max(0, cx - r):cx + r]
    if crop.size == 0:
        return None
    ok, png = cv2.imencode(".png", crop)
    return png.tobytes() if ok else None


def _png_b64(img: np.ndarray) -> str:
    ok, png = cv2.imencode(".png", img)
    return base64.b64encode(png.tobytes()).decode("ascii") if ok else ""


def _fmt_uv(uv: list | None) -> str:
    return "" if uv is None else f"u {uv[0]:.2f}, v {uv[1]:.2f}"


_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;color:#222;max-width:1200px}
table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #ccc;padding:3px 8px;font-size:14px}
th{background:#f2f2f2}.found{color:#28aa28}.displaced{color:#e67e00}.missing{color:#dc2828}
.unexpected{color:#c828c8}.not_scanned{color:#888}img{max-width:100%;border:1px solid #bbb}
.legend span{margin-right:1.5em}.muted{color:#777}
"""


def _rows(items: list[dict]) -> str:
    out = []
    for it in items:
        d, det = it["designed"] or {}, it["detection"] or {}
        dev = "" if it["deviation_m"] is None else f"{it['deviation_m'] * 1000:.0f} mm"
        out.append(
            f"<tr><td class='{it['status']}'>{html.escape(it['status'])}</td><td>{html.escape(it['class'])}</td>"
            f"<td>{html.escape(str(d.get('name') or ''))}<br><span class='muted'>{html.escape(str(d.get('guid') or ''))}</span></td>"
            f"<td>{_fmt_uv(d.get('uv'))}</td><td>{html.escape(str(det.get('id') or ''))}</td>"
            f"<td>{_fmt_uv(det.get('uv'))}</td><td>{dev}</td></tr>")
    head = ("<tr><th>status</th><th>class</th><th>designed element</th><th>designed at</th>"
            "<th>detection</th><th>found at</th><th>deviation</th></tr>")
    return f"<table>{head}{''.join(out)}</table>"


def _anchor(wall_id: str) -> str:
    return "wall-" + "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in str(wall_id))


FINDINGS = ("missing", "displaced", "unexpected")


def _findings_list(data: dict, comparison: Comparison) -> str:
    """The findings first: one line each (what, where, how far), linked to its wall's picture."""
    items = [it for it in data["items"] if it["status"] in FINDINGS]
    if not items:
        return "<h2>Findings</h2><p>None: every designed object on a scanned wall was found in place.</p>"
    items.sort(key=lambda it: (FINDINGS.index(it["status"]), str(it["wall"] or ""), it["class"]))
    lines = []
    for it in items:
        det, d = it["detection"] or {}, it["designed"] or {}
        what = f"<b class='{it['status']}'>{it['status']}</b> {html.escape(it['class'])}"
        ref = " ".join(x for x in (str(det.get("id") or ""), str(d.get("name") or "")) if x)
        dev = "" if it["deviation_m"] is None else f", {it['deviation_m'] * 1000:.0f} mm away"
        wall = it["wall"]
        where = (f"on <a href='#{_anchor(wall)}'>{html.escape(str(wall))}</a>" if wall in comparison.walls
                 else "not on a scanned wall")
        lines.append(f"<li>{what} {where}{dev}{' (' + html.escape(ref) + ')' if ref else ''}</li>")
    return f"<h2>Findings ({len(items)})</h2><ol class='findings'>{''.join(lines)}</ol>"


def render_report(comparison: Comparison, image_dir: Path | None = None) -> str:
    """The report as one HTML string."""
    data = comparison.to_dict()
    summary = data["summary"]
    esc = html.escape
    n_compared = sum(summary.get(k, 0) for k in ("found", "displaced", "unexpected"))
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<title>Scan-vs-BIM comparison</title>", f"<style>{_CSS}</style></head><body>",
        "<h1>Scan-vs-BIM comparison</h1>",
        f"<p>As-designed model: <code>{esc(str(data['as_designed']))}</code><br>"
        f"Detections: <code>{esc(str(data['detections'] or 'the review project (its current results)'))}</code>"
        f" ({n_compared} compared)<br>"
        f"Position tolerance {comparison.tolerance_m * 1000:.0f} mm; a designed object and a detection more than "
        f"{comparison.max_displacement_m:.2f} m apart are reported separately (missing + unexpected).</p>",
        "<table><tr>" + "".join(f"<th class='{k}'>{k.replace('_', ' ')}</th>" for k in summary) + "</tr><tr>"
        + "".join(f"<td>{v}</td>" for v in summary.values()) + "</tr></table>",
        "<p class='legend'><span class='found'>&#9632; found</span><span style='color:#1470c8'>&#9633; designed</span>"
        "<span class='displaced'>&#9632; displaced (arrow: designed &rarr; found)</span>"
        "<span class='missing'>&#9746; missing</span><span class='unexpected'>&#9632; unexpected</span></p>",
        _findings_list(data, comparison),
    ]
    by_wall: dict[str, list[dict]] = {}
    off_wall: list[dict] = []
    for it in data["items"]:
        if it["status"] == "not_scanned":
            continue
        (by_wall.setdefault(it["wall"], []) if it["wall"] in comparison.walls else off_wall).append(it)
    matches = data["wall_matches"]
    names = {w.guid: w.name for w in comparison.design.walls}
    for wid in comparison.walls:
        items = by_wall.get(wid, [])
        if not items:
            continue
        img, _ = wall_picture(comparison, wid, image_dir)
        designs = [names.get(g, g) for g, ws in matches.items() if wid in ws]
        title, design_label = "Wall", "design wall"
        surface = comparison.surfaces.get(wid)
        if surface is not None:  # a ceiling (tile) or a column face: its design host from its items
            title, design_label = ("Ceiling", "design ceiling") if surface.kind == "ceiling" else \
                ("Column face", "design column")
            designs = sorted({i["designed"]["design_wall"] for i in items
                              if i["designed"] and i["designed"]["design_wall"]})
        counts = {s: sum(i["status"] == s for i in items) for s in ("found", "displaced", "missing", "unexpected")}
        parts.append(f"<h2 id='{_anchor(wid)}'>{title} {esc(wid)}</h2><p class='muted'>{design_label}: "
                     f"{esc(', '.join(designs) or 'none matched')}; "
                     + ", ".join(f"{k} {v}" for k, v in counts.items()) + "</p>")
        parts.append(f"<img alt='wall {esc(wid)}' src='data:image/png;base64,{_png_b64(img)}'>")
        parts.append(_rows(items))
    if off_wall:
        parts.append("<h2>Not on a scanned wall</h2>" + _rows(off_wall))
    not_scanned = [it for it in data["items"] if it["status"] == "not_scanned"]
    if not_scanned:
        parts.append(f"<h2>Designed objects on walls the scan does not cover ({len(not_scanned)})</h2>"
                     "<p class='muted'>Not verified; no finding.</p>" + _rows(not_scanned))
    if data["unmapped_design_elements"]:
        rows = "".join(f"<tr><td>{esc(str(u['ifc_class']))}</td><td>{esc(str(u['predefined_type']))}</td>"
                       f"<td>{esc(str(u['object_type']))}</td><td>{u['count']}</td></tr>"
                       for u in data["unmapped_design_elements"])
        parts.append("<h2>Design elements mapping to no library class</h2><table><tr><th>IFC class</th>"
                     f"<th>predefined type</th><th>object type</th><th>elements</th></tr>{rows}</table>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(comparison: Comparison, path: Path, image_dir: Path | None = None) -> None:
    """Write the comparison's self-contained HTML report (:func:`render_report`).

    Parameters
    ----------
    comparison
        What :func:`~sbsc_core.bim.compare.compare` found.
    path
        The HTML file to write; its pictures are embedded.
    image_dir
        The detect output's ``orthoimages`` folder: the walls' pictures are drawn on their
        colour orthoimages; None: on plain walls.
    """
    Path(path).write_text(render_report(comparison, image_dir), encoding="utf-8")
