"""An OpenAPI document that tells the truth (contract 7, issue 10).

FastAPI's default document declares a list-shaped ``HTTPValidationError`` for 422, which
this app never sends, and no error status codes besides it. Here every operation lists
the 4xx codes it can really answer, each with the body that is really sent
(``{"detail": "..."}``, :data:`ERROR_SCHEMA`), and the bearer scheme is declared and
required on every call but ``/api/health``.

The codes of an operation come from what it is built on: its path parameters (404),
its role dependency (401, 403), the request bounds (413, 422; :mod:`app.bounds`), a
locked project (409, 423), the streamed uploads (400, 413, 415, 429), a full disk on
writes (507) and the
``HTTPException`` / ``JSONResponse`` status codes written in its own source.
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from fastapi.routing import APIRoute

ERROR_SCHEMA = {
    "title": "Error", "type": "object", "required": ["detail"],
    "properties": {"detail": {"type": "string", "description": "one line: what is wrong, with which field"}},
    "additionalProperties": True,
}
DESCRIPTIONS = {
    400: "Malformed request (e.g. a broken multipart body)", 401: "Missing, malformed or revoked API token",
    403: "The caller's role does not allow this", 404: "No such resource", 405: "Method not allowed",
    409: "Conflict with the current state (stale version, no results yet, pending detections)",
    413: "Request body too large", 415: "Unsupported file or media type",
    422: "Invalid input (field, bounds, file content)", 423: "The project is signed off (locked)",
    429: "Too many uploads in progress for this user", 501: "Not available in this installation",
    503: "Service unavailable (e.g. the 3D viewer)",
    507: "No space left on the data disk (the server works again once space is freed)",
}
_CODE_RE = re.compile(r"(?:HTTPException|UploadRefused)\(\s*(\d{3})|status_code=(\d{3})")
_SOURCES: dict[Any, str] = {}


@dataclass
class RouteInfo:
    path: str
    methods: set[str]
    path_regex: re.Pattern
    endpoint: Any


def api_routes(app: FastAPI) -> list[RouteInfo]:
    """The app's documented API routes, flattened (FastAPI >= 0.120 nests included routers)."""
    try:
        from fastapi.routing import _iter_routes_with_context
        pairs = list(_iter_routes_with_context(app.routes))
    except ImportError:  # older FastAPI: included routes are plain APIRoutes
        pairs = [(r, None) for r in app.routes]
    out = []
    for route, ctx in pairs:
        src = ctx if ctx is not None else route
        if not isinstance(route, APIRoute) or not getattr(src, "include_in_schema", True):
            continue
        regex = getattr(src, "path_regex", None) or route.path_regex
        out.append(RouteInfo(getattr(src, "path", None) or route.path,
                             set(getattr(src, "methods", None) or route.methods or ()), regex,
                             getattr(src, "endpoint", None) or route.endpoint))
    return out


def allowed_methods(app: FastAPI, path: str) -> set[str]:
    """The methods the app's API routes accept on ``path`` (empty: no route matches)."""
    out: set[str] = set()
    for route in api_routes(app):
        if route.path_regex.match(path):
            out |= route.methods
    return out


def _source(fn: Any, depth: int = 2) -> str:
    """The source of ``fn`` and of the functions of its module that it calls (``depth`` levels)."""
    key = (fn, depth)
    if key not in _SOURCES:
        try:
            text = inspect.getsource(fn)
        except (OSError, TypeError):
            text = ""
        parts = [text]
        if depth > 0:
            names = getattr(fn, "__globals__", {})
            for called in sorted(set(re.findall(r"\b([A-Za-z_]\w*)\(", text))):
                g = names.get(called)
                if inspect.isfunction(g) and g is not fn and g.__module__ == fn.__module__:
                    parts.append(_source(g, depth - 1))
        _SOURCES[key] = "\n".join(parts)
    return _SOURCES[key]


def error_codes(route: RouteInfo, operation: dict) -> set[int]:
    """The 4xx/5xx codes ``route`` can answer (see the module docstring)."""
    src = _source(route.endpoint)
    codes = {422}
    if route.path != "/api/health":
        codes |= {401, 403}
    if "{" in route.path:
        codes.add(404)
    methods = route.methods
    if methods & {"POST", "PUT", "PATCH", "DELETE"}:
        codes |= {413, 507}  # 507: a full disk (app.failures)
    elif "mkstemp" in src:
        codes.add(507)
    if "open_project" in src or "_check_open" in src or "handle_upload" in src:
        codes |= {409, 423}
    body = operation.get("requestBody", {}).get("content", {})
    if "multipart/form-data" in body or "handle_upload" in src:
        codes |= {400, 413, 415, 422, 429}
    for m in _CODE_RE.finditer(src):
        code = int(m.group(1) or m.group(2))
        if code >= 400:
            codes.add(code)
    if "_viewer_of" in src or "viewer" in route.path:
        codes.add(503)
    return codes


def truthful_openapi(app: FastAPI) -> dict:
    """The app's OpenAPI document (built once), as described in the module docstring."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(title=app.title, version=app.version, description=app.description,
                         routes=app.routes)
    comps = schema.setdefault("components", {})
    schemas = comps.setdefault("schemas", {})
    schemas.pop("HTTPValidationError", None)
    schemas.pop("ValidationError", None)
    schemas["Error"] = ERROR_SCHEMA
    comps["securitySchemes"] = {"bearerAuth": {
        "type": "http", "scheme": "bearer",
        "description": "An API token from `sbsc user add` or POST /api/users"}}
    error = {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}
    routes = {(r.path, m.lower()): r for r in api_routes(app) for m in r.methods}
    for path, ops in schema.get("paths", {}).items():
        for method, op in ops.items():
            route = routes.get((path, method))
            if route is None:
                continue
            responses = op.setdefault("responses", {})
            declared = {int(c) for c in responses if c[:1] in "45" and c.isdigit()}  # by the route itself
            for code in sorted(set(error_codes(route, op)) | declared):
                prev = responses.get(str(code), {})
                responses[str(code)] = {"description": prev.get("description") or DESCRIPTIONS.get(code, "Error"),
                                        "content": error}
            op["security"] = [] if path == "/api/health" else [{"bearerAuth": []}]
    app.openapi_schema = schema
    return schema
