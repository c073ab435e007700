"""Large files on disk: uploads streamed in chunks, checked, then moved into place.

An upload is parsed as it arrives (``python-multipart``'s streaming parser): the file
part goes in 64 KiB pieces straight into a ``.partial`` file under ``<data>/tmp`` while
its size is counted and its SHA-256 computed, so memory stays flat whatever the size.
A refused or broken upload leaves nothing behind. Scans are checked by reading them in a
separate process from their header and a bounded sample (:mod:`sbsc_core.io.scan_check`; memory
and crashes of the readers stay out of the server), model
libraries by :func:`sbsc_core.io.models.library_from_zip`.
"""

from __future__ import annotations

import contextlib
import hashlib
import multiprocessing as mp
import os
import re
import shutil
import tempfile
import uuid
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePath

from python_multipart import MultipartParser
from python_multipart.multipart import parse_options_header
from starlette.requests import ClientDisconnect, Request

from sbsc_core.errors import InputError

from .failures import DISK_FULL, disk_full

ZIP_SUFFIXES = (".zip",)
MULTIPART_OVERHEAD = 64 * 1024  # boundaries and part headers beyond the file's own bytes
MAX_FIELD_BYTES = 64 * 1024  # a non-file form field


class UploadRefused(Exception):
    """An upload that is refused: an HTTP status and a one-line reason."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


@dataclass
class ReceivedFile:
    path: Path  # the partial file (delete or move it)
    filename: str  # sanitised client file name
    size: int
    sha256: str

    def discard(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()


def safe_filename(name: str, default: str = "upload", max_len: int = 120) -> str:
    """The last path component with only ``[A-Za-z0-9._-]`` kept (others become ``_``); a
    longer name than ``max_len`` is shortened in its stem, so it keeps its extension."""
    base = PurePath(name.replace("\\", "/")).name
    base = re.sub(r"[^A-Za-z0-9._-]", "_", base).lstrip(".")
    if len(base) > max_len:
        stem, suffix = os.path.splitext(base)
        suffix = suffix if len(suffix) <= 16 else ""
        base = stem[:max_len - len(suffix)] + suffix
    return base or default


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


class _FilePart:
    """Receives one multipart body; writes the ``field`` file part into ``tmp_dir``."""

    def __init__(self, field: str, tmp_dir: Path, max_bytes: int, suffixes: tuple[str, ...]) -> None:
        self.field, self.tmp_dir, self.max_bytes, self.suffixes = field, tmp_dir, max_bytes, suffixes
        self.header_name = b""
        self.header_value = b""
        self.disposition = b""
        self.in_file = False
        self.field_bytes = 0
        self.part_name = ""
        self.fh = None
        self.path: Path | None = None
        self.filename = ""
        self.size = 0
        self.hash = hashlib.sha256()
        self.ended = False

    # python-multipart callbacks --------------------------------------------------------
    def on_part_begin(self) -> None:
        self.disposition, self.in_file, self.field_bytes = b"", False, 0

    def on_header_field(self, data: bytes, start: int, end: int) -> None:
        self.header_name += data[start:end]

    def on_header_value(self, data: bytes, start: int, end: int) -> None:
        self.header_value += data[start:end]

    def on_header_end(self) -> None:
        if self.header_name.lower() == b"content-disposition":
            self.disposition = self.header_value
        self.header_name, self.header_value = b"", b""

    def on_headers_finished(self) -> None:
        _, opts = parse_options_header(self.disposition)
        name = opts.get(b"name", b"").decode("utf-8", "replace")
        self.part_name = name
        if name != self.field and b"filename" in opts:
            raise UploadRefused(400, f"no `{self.field}` field: send the file in the multipart field "
                                     f"'{self.field}' (it came in '{name[:40]}')")
        if name != self.field or b"filename" not in opts:
            return
        if self.path is not None:
            raise UploadRefused(400, f"one file per upload: field '{self.field}' appears twice")
        self.filename = safe_filename(opts[b"filename"].decode("utf-8", "replace"))
        suffix = Path(self.filename).suffix.lower()
        if suffix not in self.suffixes:
            raise UploadRefused(415, f"{self.filename}: unsupported file type '{suffix or '(none)'}' "
                                     f"(expected {', '.join(self.suffixes)})")
        self.tmp_dir.mkdir(parents=True, exist_ok=True)
        self.path = self.tmp_dir / f"upload-{uuid.uuid4().hex}.partial{suffix}"
        self.fh = open(self.path, "wb", buffering=1 << 20)  # noqa: SIM115 - closed in finish()
        self.in_file = True

    def on_part_data(self, data: bytes, start: int, end: int) -> None:
        n = end - start
        if not self.in_file:
            self.field_bytes += n
            if self.field_bytes > MAX_FIELD_BYTES:  # a file sent as a plain field, or under another name
                raise UploadRefused(400, f"no `{self.field}` field: send the file in the multipart field "
                                         f"'{self.field}', with a file name (field '{self.part_name[:40]}' is "
                                         "not a file upload)")
            return
        self.size += n
        if self.size > self.max_bytes:
            raise UploadRefused(413, f"{self.filename}: file too large "
                                     f"(more than {self.max_bytes:,} bytes allowed)")
        chunk = data[start:end]
        self.hash.update(chunk)
        try:
            self.fh.write(chunk)
        except OSError as exc:
            if disk_full(exc):
                raise UploadRefused(507, DISK_FULL) from exc
            raise

    def on_part_end(self) -> None:
        self.in_file = False

    def on_end(self) -> None:
        self.ended = True

    def callbacks(self) -> dict:
        return {k: getattr(self, k) for k in (
            "on_part_begin", "on_header_field", "on_header_value", "on_header_end",
            "on_headers_finished", "on_part_data", "on_part_end", "on_end")}

    def close(self, keep: bool) -> None:
        """Close the partial file, and remove it unless ``keep``; also when closing fails
        (a full disk fails the last flush): a partial file never stays behind."""
        fh, self.fh = self.fh, None
        closed = False
        try:
            if fh is not None:
                fh.close()
            closed = True
        finally:
            if (not keep or not closed) and self.path is not None:
                with contextlib.suppress(FileNotFoundError):
                    self.path.unlink()


async def receive_file(request: Request, *, tmp_dir: Path, max_bytes: int, drain_bytes: int,
                       suffixes: tuple[str, ...], field: str = "file") -> ReceivedFile:
    """Stream the multipart ``field`` of ``request`` to a partial file; raise UploadRefused.

    A body that is refused for its size is read and dropped up to ``drain_bytes`` so that
    the client gets the 413 answer rather than a reset connection; past that it is cut.
    """
    ctype, params = parse_options_header(request.headers.get("content-type", ""))
    if ctype != b"multipart/form-data" or b"boundary" not in params:
        raise UploadRefused(415, f"expected a multipart/form-data body with a field '{field}'")
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > max_bytes + MULTIPART_OVERHEAD:
        raise UploadRefused(413, f"upload too large ({int(declared):,} bytes; "
                                 f"at most {max_bytes:,} allowed)")
    part = _FilePart(field, tmp_dir, max_bytes, suffixes)
    parser = MultipartParser(params[b"boundary"], part.callbacks())
    stream = request.stream()
    ok = False
    try:
        try:
            async for chunk in stream:
                parser.write(chunk)
                if part.ended:
                    break
        except UploadRefused as exc:
            if exc.status in (413, 507):
                part.close(keep=False)
                drained = 0
                with contextlib.suppress(ClientDisconnect):
                    async for chunk in stream:
                        drained += len(chunk)
                        if drained > drain_bytes:
                            break
            raise
        except ClientDisconnect:
            raise UploadRefused(400, "upload interrupted: the client went away") from None
        except ValueError as exc:  # python-multipart parse errors
            raise UploadRefused(400, f"malformed multipart body ({exc})") from None
        if part.path is None:
            raise UploadRefused(400, f"no `{field}` field: the multipart field '{field}' with a file is missing")
        if not part.ended:
            raise UploadRefused(400, f"{part.filename}: upload incomplete "
                                     "(the body ended before its closing boundary)")
        if part.size == 0:
            raise UploadRefused(422, f"{part.filename}: empty file")
        ok = True
    finally:
        try:
            part.close(keep=ok)
        except OSError as exc:
            if disk_full(exc):
                raise UploadRefused(507, DISK_FULL) from exc
            raise
    return ReceivedFile(path=part.path, filename=part.filename, size=part.size,
                        sha256=part.hash.hexdigest())


# --------------------------------------------------------------------------- scan check


def _count_points(path: str, filename: str, conn) -> None:  # noqa: ANN001 - a Connection
    """Child process: check the scan's header and a sample, send ("ok", n) or ("error", reason)."""
    try:
        from sbsc_core.io.scan_check import ScanRefused, count_points

        try:
            conn.send(("ok", count_points(Path(path))))
        except ScanRefused as exc:
            conn.send(("error", f"{filename}: {exc}"))
    except MemoryError:
        conn.send(("error", f"{filename}: too large to read"))
    except Exception as exc:  # noqa: BLE001 - any reader failure is the file's fault here
        conn.send(("error", f"{filename}: cannot read ({type(exc).__name__})"))
    finally:
        conn.close()


def check_scan(path: Path, filename: str, timeout_s: float) -> int:
    """Count the points of a scan from its header and check a sample of it
    (:mod:`sbsc_core.io.scan_check`) in a child process; raise UploadRefused(422).

    Memory stays bounded by the sample whatever the file's size; a reader that crashes or
    takes longer than ``timeout_s`` refuses the file too.
    """
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_count_points, args=(str(path), filename, child), daemon=True,
                       name="sbsc-scan-check")
    proc.start()
    child.close()
    try:
        if not parent.poll(timeout_s):
            raise UploadRefused(422, f"{filename}: reading took longer than {timeout_s:.0f} s")
        try:
            status, value = parent.recv()
        except EOFError:
            proc.join(5)
            raise UploadRefused(422, f"{filename}: the reader crashed "
                                     f"(exit code {proc.exitcode})") from None
    finally:
        parent.close()
        if proc.is_alive():
            proc.kill()
        proc.join(5)
    if status != "ok":
        raise UploadRefused(422, str(value))
    return int(value)


# --------------------------------------------------------------------------- model libraries


def check_zip(path: Path, filename: str, *, max_entries: int, max_entry_bytes: int,
              max_total_bytes: int, max_ratio: float) -> None:
    """Entry by entry before unpacking: count, declared sizes, compression ratio, names.

    :func:`sbsc_core.io.models.library_from_zip` checks names and sizes again while it
    unpacks (sizes actually decompressed, not the declared ones).
    """
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise UploadRefused(422, f"{filename}: not a readable zip file ({exc})") from None
    with zf:
        infos = zf.infolist()
        if len(infos) > max_entries:
            raise UploadRefused(422, f"{filename}: too many entries ({len(infos)} > {max_entries})")
        total = 0
        for info in infos:
            name = info.filename
            parts = PurePath(name.replace("\\", "/")).parts
            if name.startswith(("/", "\\")) or ".." in parts or (parts and ":" in parts[0]):
                raise UploadRefused(422, f"{filename}: {name}: path leaves the library directory")
            if (info.external_attr >> 16) & 0o170000 == 0o120000:
                raise UploadRefused(422, f"{filename}: {name}: symbolic links are not allowed")
            if info.file_size > max_entry_bytes:
                raise UploadRefused(422, f"{filename}: {name}: entry too large "
                                         f"({info.file_size:,} > {max_entry_bytes:,} bytes)")
            if info.file_size > 1 << 20 and info.file_size > max_ratio * max(info.compress_size, 1):
                raise UploadRefused(422, f"{filename}: {name}: compression ratio too high "
                                         "(a zip bomb?)")
            total += info.file_size
            if total > max_total_bytes:
                raise UploadRefused(422, f"{filename}: unpacks to more than {max_total_bytes:,} bytes")


def unpack_library(zip_path: Path, filename: str, dest: Path) -> tuple[Path, dict]:
    """Unpack and load the library into ``dest``; returns (root, class id -> model.json fields)."""
    from sbsc_core.io.models import library_from_zip, load_model_library

    try:
        root = library_from_zip(zip_path, dest)
        library = load_model_library(root)
    except InputError as exc:
        shutil.rmtree(dest, ignore_errors=True)
        msg = str(exc).replace(str(zip_path.parent) + os.sep, "").replace(zip_path.name, filename)
        raise UploadRefused(422, msg) from None
    return root, library_summary(library)


def library_summary(library) -> dict:  # noqa: ANN001 - sbsc_core.types.ModelLibrary
    return {cid: {"name": m.name, "ifc_class": m.ifc_class, "predefined_type": m.predefined_type,
                  "width_m": float(m.width_m), "height_m": float(m.height_m), "mount": list(m.mount)}
            for cid, m in sorted(library.models.items())}


# --------------------------------------------------------------------------- housekeeping


def move_into_place(src: Path, dest: Path) -> None:
    dest.parent.mkdir(parents=True, exist_ok=True)
    os.replace(src, dest)


def project_file(pid: int, kind: str, filename: str) -> Path:
    """Relative path (under the data dir) for a new stored file of project ``pid``."""
    return Path("projects", str(pid), kind, f"{uuid.uuid4().hex[:12]}_{filename}")


@contextlib.contextmanager
def removed_on_failure(dest: Path) -> Iterator[Path]:
    """Yield ``dest``; if the block fails (e.g. the row's commit after the file was moved into
    place), the file is removed again, so no stored file is left without its row."""
    try:
        yield dest
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            dest.unlink()
        raise


def clean_tmp(tmp_dir: Path) -> int:
    """Remove what a previous run left in the scratch directory; returns how many entries."""
    n = 0
    if not tmp_dir.is_dir():
        return 0
    for p in tmp_dir.iterdir():
        n += 1
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    return n


def scratch_dir(tmp_dir: Path, prefix: str) -> Path:
    tmp_dir.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=prefix, dir=tmp_dir))


def sweep_orphans(projects_dir: Path, data_dir: Path, scan_paths: set[str], model_paths: set[str],
                  job_ids: set[int]) -> list[Path]:
    """Remove files a crash left without a database row; returns what was removed.

    A scan or library is moved into place just before its row is committed, a job's
    output is written before its results are: a crash in between leaves files nobody
    refers to. Referenced paths are relative to ``data_dir`` (posix).
    """
    removed: list[Path] = []
    if not projects_dir.is_dir():
        return removed
    for pdir in projects_dir.iterdir():
        for p in sorted((pdir / "scans").glob("*")):
            if p.relative_to(data_dir).as_posix() not in scan_paths:
                removed.append(p)
                with contextlib.suppress(FileNotFoundError):
                    p.unlink()
        for p in sorted((pdir / "models").glob("*")):
            rel = p.relative_to(data_dir).as_posix()
            if not any(m == rel or m.startswith(rel + "/") for m in model_paths):
                removed.append(p)
                shutil.rmtree(p, ignore_errors=True)
        for p in sorted((pdir / "jobs").glob("*")):
            if not (p.name.isdigit() and int(p.name) in job_ids):
                removed.append(p)
                shutil.rmtree(p, ignore_errors=True)
    return removed
