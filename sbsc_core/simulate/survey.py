"""A survey frame at large coordinates (``sbsc simulate --survey-frame``).

Real scans come georeferenced: a projected frame such as UTM puts a building near
(412000, 5612000, 100) m and turns its plan by some angle. :class:`SurveyFrame` maps the
simulator's local frame to such a frame, ``world = R_z(rotation_deg) local + offset``, and
is applied to the scan (written as double-precision PLY, since float32 has only ~0.5 m
resolution at 5.6e6 m) and to every point and direction of the ground truth alike, so
that both stay consistent: objects, walls, distractors, surfaces (a round column's plan
``centre`` too), columns (plan ``centre``, ``floor_z``), storeys (``floor_z``,
``ceiling_z``, ``room_ceilings``) and stations. The truth records the frame under
``survey_frame``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

UTM_LIKE_OFFSET = (412000.0, 5612000.0, 100.0)
DEFAULT_ROTATION_DEG = 23.5

_POINT_KEYS = ("position", "centre", "origin")  # [x, y, z], or a plan point [x, y]
_VECTOR_KEYS = ("normal", "axis_u", "axis_v")
_LEVEL_KEYS = ("floor_z", "ceiling_z")


@dataclass(frozen=True)
class SurveyFrame:
    offset: tuple[float, float, float] = UTM_LIKE_OFFSET
    rotation_deg: float = DEFAULT_ROTATION_DEG

    @property
    def rotation(self) -> np.ndarray:
        a = math.radians(self.rotation_deg)
        return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])

    def points(self, xyz: np.ndarray, chunk: int = 5_000_000) -> np.ndarray:
        """Local points (any float type) to float64 survey coordinates, in chunks."""
        out = np.empty((len(xyz), 3), np.float64)
        rot_t, off = self.rotation.T, np.asarray(self.offset, np.float64)
        for s in range(0, len(xyz), chunk):
            out[s:s + chunk] = np.asarray(xyz[s:s + chunk], np.float64) @ rot_t + off
        return out

    def vectors(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, np.float64) @ self.rotation.T

    def level(self, z: float) -> float:
        """A height (a floor or ceiling level) in the survey frame."""
        return float(z) + float(self.offset[2])

    def _point(self, p: list) -> list[float]:
        """A point [x, y, z] or a plan point [x, y] in the survey frame, rounded."""
        if len(p) == 2:
            return [round(float(x), 5) for x in self.points(np.array([[p[0], p[1], 0.0]]))[0][:2]]
        return [round(float(x), 5) for x in self.points(np.array([p]))[0]]

    def truth(self, doc: dict) -> dict:
        """A ground-truth document (contract 5) moved into the survey frame (a new dict)."""
        out = dict(doc)

        def item(d: dict) -> dict:
            d = dict(d)
            for k in _POINT_KEYS:
                if k in d:
                    d[k] = self._point(d[k])
            for k in _VECTOR_KEYS:
                if k in d:
                    d[k] = [round(float(x), 6) for x in self.vectors(np.array(d[k]))]
            for k in _LEVEL_KEYS:
                if k in d:
                    d[k] = round(self.level(d[k]), 5)
            if "room_ceilings" in d:
                d["room_ceilings"] = {r: round(self.level(z), 5) for r, z in d["room_ceilings"].items()}
            return d

        for key in ("objects", "walls", "distractors", "surfaces", "columns", "storeys"):
            if key in doc:
                out[key] = [item(d) for d in doc[key]]
        if "stations" in doc:
            out["stations"] = [[round(float(x), 4) for x in p] for p in self.points(np.array(doc["stations"]))]
        if "registration_errors" in doc:
            out["registration_errors"] = [
                {**r, "translation_m": [round(float(x), 6) for x in self.vectors(np.array(r["translation_m"]))]}
                for r in doc["registration_errors"]]
        out["survey_frame"] = {"offset": list(self.offset), "rotation_deg": self.rotation_deg}
        return out
