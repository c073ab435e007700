"""Images of a surface: the scan partitioned per wall, orthoimages, occlusion, colour preparation and the wall's area and openings."""
