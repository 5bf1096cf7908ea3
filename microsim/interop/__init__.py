"""Tables handed to other tools: exports (MERL, netCDF grids), the Mitsuba 3 BSDF plugin, renders."""
