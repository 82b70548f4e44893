"""The queries on a prepared scene: render, cast and occluded, and their checks."""
