"""Helpers of the browser tests: Debian chromium and its flags, viewports, logging in."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from .app_support import ROOT

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


def chromium_path() -> str | None:
    """Debian's chromium; installed with apt-get (we run as root) when it is missing."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found:
        return found
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        return None
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "install", "-y", "-qq", "chromium"],
                ["sh", "-c", "apt-get update -qq && apt-get install -y -qq chromium"]):
        if subprocess.run(cmd, env=env, capture_output=True, timeout=900).returncode == 0:
            break
    return shutil.which("chromium")


VIEW = {"width": 1400, "height": 900}


GL = ["--use-gl=swiftshader", "--enable-unsafe-swiftshader"]


def login(page, srv) -> None:  # noqa: ANN001
    page.goto(srv.url + "/")
    page.fill("#token", srv.token)
    page.click("#login-form button[type=submit]")
    page.wait_for_selector("#new-name")


VIEWPORT = {"width": 1440, "height": 900}


LONG_CLASSES = ("fire_alarm_switch_sign", "extinguisher_sign", "electrical_panel", "builtin_socket")


DISPLAY_NAMES = {c: json.loads((ROOT / "sbsc_core" / "data" / "models" / c / "model.json").read_text())["name"]
                 for c in LONG_CLASSES}


SHOTS = (ROOT / "docs" / "images" if os.environ.get("SBSC_SAVE_SCREENSHOTS") == "1"
         else Path(tempfile.gettempdir()) / "sbsc-screenshots")
