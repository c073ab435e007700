"""Settings of the review app, read the pydantic-settings way from ``SBSC_*`` variables.

``SBSC_DATA_DIR`` holds the embedded SQLite database and every large file (scans,
model libraries, job outputs); ``SBSC_DATABASE_URL`` points at another database
(e.g. ``postgresql+psycopg://user@host/sbsc``) while files stay under the data dir.
"""

from __future__ import annotations

import os
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

MiB = 1024 * 1024
GiB = 1024 * MiB


def default_data_dir() -> Path:
    """``$XDG_DATA_HOME/sbsc`` (``~/.local/share/sbsc``), or ``%APPDATA%\\sbsc`` on Windows."""
    if os.name == "nt" and os.environ.get("APPDATA"):
        return Path(os.environ["APPDATA"]) / "sbsc"
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "sbsc"


def default_static_dir() -> Path:
    """The pages shipped as package data in ``app/static/``."""
    return Path(__file__).resolve().parent / "static"


class AppSettings(BaseSettings):
    """Everything the web app can be told; each field is ``SBSC_<NAME>`` in the environment."""

    model_config = SettingsConfigDict(env_prefix="SBSC_", extra="ignore")

    data_dir: Path = Field(default_factory=default_data_dir)
    database_url: str | None = None  # default: sqlite file sbsc.db in data_dir
    static_dir: Path = Field(default_factory=default_static_dir)

    threads: int = 8  # worker threads of the web process for blocking endpoints

    # uploads
    max_scan_bytes: int = 8 * GiB
    max_models_zip_bytes: int = 256 * MiB
    max_design_bytes: int = 512 * MiB  # as-designed IFC files
    upload_drain_bytes: int = 32 * MiB  # a refused body is read and dropped up to this, then cut
    scan_check_timeout_s: float = 600.0  # header + sample check of one scan (sbsc_core.io.scan_check)
    uploads_per_user: int = 2  # uploads of one user in progress at once (more: 429)
    upload_check_workers: int = 2  # checks of uploaded files run at most this many at once
    max_json_body_bytes: int = 1 * MiB  # a JSON request body (uploads have their own caps)
    max_json_depth: int = 16  # nesting of a JSON request body
    max_json_keys: int = 1000  # keys of one object in a JSON request body
    zip_max_entries: int = 5000
    zip_max_entry_bytes: int = 64 * MiB
    zip_max_total_bytes: int = 1 * GiB
    zip_max_ratio: float = 200.0  # uncompressed / compressed per entry (zip bombs)

    # jobs
    job_workers: int = 1
    job_runner: str = "sbsc_core.pipeline:detect_to_dir"  # "module:function" with its signature
    job_timeout_s: float = 6 * 3600.0
    job_poll_s: float = 0.25  # supervisor tick
    progress_min_interval_s: float = 0.3  # worker writes progress at most this often

    # review
    thumbnail_px: int = 160
    thumbnail_context: float = 2.5  # crop side = this x the object's larger side (min below)
    thumbnail_min_m: float = 0.25

    # 3D review scenes (app.viewer, viser): one server per project on a free port of this host
    viewer: bool = True
    viewer_host: str = "127.0.0.1"
    viewer_idle_s: float = 900.0  # a project scene no tab has been on for this long is stopped

    # exports: the organisation named in the header of IFC files (SBSC_ORGANISATION)
    organisation: str = ""

    # slow clients (app.slow_clients; uvicorn's own limits where it has them)
    http_header_timeout_s: float = 10.0  # a request's line and headers must arrive within this
    http_body_idle_s: float = 30.0  # a request body that stops arriving for this long is dropped
    http_keep_alive_s: float = 5.0  # idle time between requests on a kept-alive connection
    http_limit_concurrency: int = 1000  # open connections + requests in progress (more: 503)
    http_max_header_bytes: int = 16 * 1024  # request line and headers (more: 400)
    http_backlog: int = 2048  # connections waiting to be accepted

    # first run
    create_admin_on_first_run: bool = True

    @property
    def db_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'sbsc.db').as_posix()}"

    @property
    def tmp_dir(self) -> Path:
        """Partial uploads and job scratch space; emptied at start-up."""
        return self.data_dir / "tmp"

    @property
    def projects_dir(self) -> Path:
        return self.data_dir / "projects"

    def ensure_dirs(self) -> None:
        for d in (self.data_dir, self.tmp_dir, self.projects_dir):
            d.mkdir(parents=True, exist_ok=True)
