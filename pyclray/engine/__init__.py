"""The engine: OpenCL devices and the program cache, the kernels (package data in kernels/), the
acceleration structures, the scene prepared for the device, and render / cast / occluded on it.
It imports the model only."""
