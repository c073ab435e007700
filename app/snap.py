"""Place an object a reviewer added where its depth model matches the wall's relief nearby.

The logic lives in the library (:mod:`sbsc_core.recognition.learning.snap`, also used by ``sbsc learn``);
this module keeps the review app's imports.
"""

from sbsc_core.recognition.learning.snap import (
    MIN_NCC,
    MIN_RELIEF_M,
    SEARCH_RADIUS_M,
    Snap,
    depth_template,
    snap_to_relief,
)

__all__ = ["MIN_NCC", "MIN_RELIEF_M", "SEARCH_RADIUS_M", "Snap", "depth_template", "snap_to_relief"]
