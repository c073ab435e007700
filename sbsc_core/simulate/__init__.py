"""A virtual building and a virtual terrestrial laser scanner (the paper used Blensor)."""
