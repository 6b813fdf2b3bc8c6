"""The version of vibsynth: written here only (pyproject.toml reads it; every layer may import it)."""

__version__ = "0.1.0"
