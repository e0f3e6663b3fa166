"""Low-level operators: finite differences, warping, pyramids, ROF, median, prox."""
