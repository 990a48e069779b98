"""The bottom layer: what every layer may use (the errors)."""
