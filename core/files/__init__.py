"""Files: images, PLY, atomic writes read back, safe names."""
