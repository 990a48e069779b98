"""Selected to active: the high-poly input, the automatic extrusion, the matching start stage."""
