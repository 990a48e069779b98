"""Monte Carlo as a library: point sets on the unit square, warps to shapes, integration, statistics, exact answers."""
