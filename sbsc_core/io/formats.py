"""The scan formats of contract 1, one line each: the extension, its reader, its upload check
and the reader of the coordinate system its files record.

The one table of them: :func:`~sbsc_core.io.scans.scan_extensions` (the CLI's help, the upload
page, the upload's suffix check) and the readers and checks come from here. A new format is a
reader module ``scan_<format>.py``, its header check (``scan_check.py``) and a line here. Imported with :mod:`sbsc_core.io`.
"""

from __future__ import annotations

from . import scan_check as check
from .crs import e57_crs, las_crs
from .scan_e57 import _read_e57
from .scan_las import _read_las
from .scan_pcd import _read_pcd
from .scan_ply import _read_ply
from .scan_text import _read_pts, _read_xyz
from .scans import register_reader

FORMATS = (  # extension, reader, upload check, the coordinate system the file records
    (".ply", _read_ply, check.ply_points, None),
    (".e57", _read_e57, check.e57_points, e57_crs),
    (".las", _read_las, check.las_points, las_crs),
    (".laz", _read_las, check.las_points, las_crs),
    (".pcd", _read_pcd, check.pcd_points, None),
    (".xyz", _read_xyz, check.text_points, None),
    (".pts", _read_pts, check.pts_points, None),
    (".txt", _read_xyz, check.text_points, None),
)

for _ext, _reader, _count, _crs in FORMATS:
    register_reader(_ext, _reader, count=_count, crs=_crs)
