"""The package's version (setup.cfg reads it; the CLI prints it when the package is not installed)."""

__version__ = "0.1.0"
