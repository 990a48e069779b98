"""The engine: sample patterns, the kernel, the tile baker, estimators, adaptive sampling, the scheduler, a bake's settings."""
