"""sbsc_core: recognition of secondary building service components in coloured laser scans.

The method follows Adán et al., "Scan-to-BIM for 'secondary' building components"
(sections 3-5): walls are turned into 4D orthoimages (RGB + depth), objects are found
independently in depth and in colour, and a consensus step fuses both.
"""

__version__ = "0.1.0"
