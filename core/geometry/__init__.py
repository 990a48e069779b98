"""Geometry: the mesh, the UV rasteriser, sample units on the surface, the margin."""
