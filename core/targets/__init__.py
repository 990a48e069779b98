"""What a bake fills: texels of an image, UDIM tiles, mesh corners, maps of several quantities."""
