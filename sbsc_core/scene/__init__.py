"""The scanned building's shape: storeys, floor and ceiling, walls, ceilings, columns, the stations' registration and stray points."""
