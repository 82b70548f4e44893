"""The scene model: what a scene is (camera, image, shapes, lights, shading, animation), the one
table of AOVs, the errors, and reading scene files. It imports nothing of the layers above it
(engine, io, reference, apps)."""
