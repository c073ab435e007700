"""Finding objects on an orthoimage: templates, matching in depth and colour, look-alikes, consensus, confidence, mounting, duplicates, placement, suggestions and learning new classes."""
