"""The pipeline every bake runs and the public calls."""
