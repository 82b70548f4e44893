"""Bounding volume hierarchies: the trees, their builders and packings, and screen tiles."""
