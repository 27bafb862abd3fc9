"""The version of gainlink (one place: the package, the CLI, artifacts' provenance and campaign keys read it)."""

__version__ = "0.1.0"
