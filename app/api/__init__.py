"""The REST API (contract 7): one router per concern, all under ``/api``."""
