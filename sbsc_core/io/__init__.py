"""Readers and writers for the formats of ``CONTRACTS.md``."""

from . import formats  # noqa: F401 - registers the scan formats' readers and checks
