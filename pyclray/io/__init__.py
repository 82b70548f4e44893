"""Outputs: EXR, PNG previews and their colour maps, the band writer of a render's files, video and
frame folders, progress on a terminal; one module each. Imports the model only."""
