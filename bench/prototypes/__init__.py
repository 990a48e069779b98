"""Measured prototypes kept for their figures: not run by the bench or the tests."""
