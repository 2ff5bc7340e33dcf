"""The one place the version is written (the wheel's metadata and the assets' provenance read it)."""

__version__ = "0.1.0"
