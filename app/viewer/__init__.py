"""The 3D review scene of a project (viser), beside the REST API.

``backend``   the ReviewBackend Protocol the scene talks to, and an in-memory backend
``lod``       the scan's browser level of detail, cached on disk
``images``    orthoimage textures and object crops
``scene``     ProjectScene: the layers, the per-tab review panel, the change-feed sync
``manager``   ViewerManager: one viser server per project, on its own port
``api``       viewer_router(): GET /api/projects/{pid}/viewer -> {"url": ...}
``db_backend`` the ReviewBackend on the review service's database
"""
