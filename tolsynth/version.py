"""The package version, in one place (the tables and reports record it)."""

__version__ = "0.1.0"
