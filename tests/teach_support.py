"""The teach-and-search-again scene (issue 28): the fake runner plus four card readers no library
knows, and a project with one finished job. Shared by ``test_app_teach`` and its browser test."""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from .app_support import PIXEL_M, _fake_output

RUNNER = "tests.teach_support:fake_with_card_readers"


READERS = [(0.6, 1.5), (1.4, 1.5), (2.2, 1.5), (2.6, 0.8)]  # (u, v) on W01


READER_SIZE = (0.10, 0.14)


READER_COLOUR = (40, 90, 160)  # RGB


WALL_H = 2.5


def _learnt_reader_class(models: Path) -> str | None:
    """A class of ``models`` learnt from examples whose size is a card reader's."""
    for meta_path in sorted(Path(models).glob("*/model.json")):
        meta = json.loads(meta_path.read_text())
        if meta.get("learnt_from") and abs(meta["width_m"] - READER_SIZE[0]) < 0.03 \
                and abs(meta["height_m"] - READER_SIZE[1]) < 0.03:
            return meta_path.parent.name
    return None


def fake_with_card_readers(scans: Sequence[Path], models: Path, *, expected=None, out: Path,  # noqa: ANN001
                           settings_file=None, log=None, progress=None) -> dict:  # noqa: ANN001
    """The fake runner's output plus four card readers on W01, found once a class of them is learnt."""
    control = Path(os.environ.get("SBSC_DATA_DIR", ".")) / "fake_control.json"  # app_support.fake_control
    delay_s = float(json.loads(control.read_text()).get("delay_s", 0.2)) if control.is_file() else 0.2
    summary = _fake_output(Path(out), 8, progress or (lambda s, f: None), delay_s)
    img = Path(out) / "orthoimages"
    colour = cv2.imread(str(img / "W01_colour.png"), cv2.IMREAD_COLOR)
    depth = np.load(img / "W01_depth.npy")
    w, h = READER_SIZE
    for u, v in READERS:
        c0, c1 = int((u - w / 2) / PIXEL_M), int((u + w / 2) / PIXEL_M)
        r0, r1 = int((WALL_H - v - h / 2) / PIXEL_M), int((WALL_H - v + h / 2) / PIXEL_M)
        colour[r0:r1, c0:c1] = READER_COLOUR[::-1]
        depth[r0:r1, c0:c1] = 0.015
    cv2.imwrite(str(img / "W01_colour.png"), colour)
    np.save(img / "W01_depth.npy", depth)
    cls = _learnt_reader_class(models)
    if cls is not None:
        doc = json.loads((Path(out) / "detections.json").read_text())
        for k, (u, v) in enumerate(READERS):
            doc["detections"].append({"id": f"D{100 + k:04d}", "class": cls, "wall": "W01",
                                      "position": [u, 0.0, v], "u": u, "v": v, "width_m": w, "height_m": h,
                                      "alpha": 0.55 + 0.01 * k, "rho_depth": 0.8, "rho_colour": 0.5,
                                      "source": "both"})
        (Path(out) / "detections.json").write_text(json.dumps(doc))
        summary["detections"] += len(READERS)
    return summary


