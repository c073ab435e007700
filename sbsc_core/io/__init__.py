"""Readers and writers for the formats of ``CONTRACTS.md``."""
