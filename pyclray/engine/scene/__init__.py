"""A scene on the device: its packed shapes, the per-view pass, refits, lights and views."""
