"""The scan formats of contract 1, one line each: the extension, its reader and its upload check.

The one table of them: :func:`~sbsc_core.io.scans.scan_extensions` (the CLI's help, the upload
page, the upload's suffix check) and the readers and checks come from here. A new format is a
reader (and its header check) and a line here. Imported with :mod:`sbsc_core.io`.
"""

from __future__ import annotations

from . import scan_check as check
from . import scans

FORMATS = (
    (".ply", scans._read_ply, check.ply_points),
    (".e57", scans._read_e57, check.e57_points),
    (".las", scans._read_las, check.las_points),
    (".laz", scans._read_las, check.las_points),
    (".pcd", scans._read_pcd, check.pcd_points),
    (".xyz", scans._read_xyz, check.text_points),
    (".pts", scans._read_pts, check.pts_points),
    (".txt", scans._read_xyz, check.text_points),
)

for _ext, _reader, _count in FORMATS:
    scans.register_reader(_ext, _reader, count=_count)
