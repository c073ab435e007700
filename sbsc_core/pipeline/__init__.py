"""Running the stages on a whole scan: orchestration, local and Dask executors, outputs.

``detect`` (a cloud in memory), ``detect_scans`` (scan files, streamed) and ``detect_to_dir``
(``sbsc detect``: the output folder of contract 4) are the entry points; the review app's jobs
call ``sbsc_core.pipeline:detect_to_dir``.
"""

from .detect import detect, detect_scans, detect_to_dir
from .outputs import DetectionResult

__all__ = ["DetectionResult", "detect", "detect_scans", "detect_to_dir"]
