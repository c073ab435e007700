"""JSON Schemas of the file formats, generated from the pydantic models that read them.

``docs/schemas/*.schema.json`` are these schemas, written by

    python -m sbsc_core.io.schemas docs/schemas

and a test keeps the files equal to what the code generates and validates real outputs
(``sbsc detect``'s ``detections.json``, the review app's documents) against them. The
models check more than a schema can say (finite numbers within bounds, known class ids);
the schemas give the shape, for tools outside Python.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from .detections_model import DetectionsDocument

SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
MODELS: dict[str, tuple[type[BaseModel], str]] = {
    "detections": (DetectionsDocument, "Contract 4: detections.json (sbsc.detections/1), written by "
                                       "sbsc detect and served by the review app"),
}


def json_schemas() -> dict[str, dict[str, Any]]:
    """Name -> JSON Schema (draft 2020-12) of every format that has a pydantic model."""
    out = {}
    for name, (model, description) in MODELS.items():
        schema = model.model_json_schema(by_alias=True)
        out[name] = {"$schema": SCHEMA_DIALECT, "$id": f"https://sbsc.invalid/schemas/{name}.schema.json",
                     **schema, "description": description}
    return out


def schema_text(schema: dict[str, Any]) -> str:
    return json.dumps(schema, indent=1, sort_keys=True) + "\n"


def write_schemas(folder: Path) -> list[Path]:
    """Write ``<name>.schema.json`` for every schema into ``folder``; returns the files."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, schema in json_schemas().items():
        path = folder / f"{name}.schema.json"
        path.write_text(schema_text(schema), encoding="utf-8")
        written.append(path)
    return written


if __name__ == "__main__":
    for p in write_schemas(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/schemas")):
        print(p)
