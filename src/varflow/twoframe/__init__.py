"""Two-frame optical flow methods and the coarse-to-fine driver they share."""
