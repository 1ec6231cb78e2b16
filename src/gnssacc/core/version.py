"""The package version (one place: the package, the output folders and campaigns record it)."""

__version__ = "0.1.0"
