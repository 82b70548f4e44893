"""OpenCL devices, contexts, buffers and PoCL's CPU name: the engine's ground floor."""
