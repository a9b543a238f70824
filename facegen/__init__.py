"""facegen: speech (audio + transcript) to expressive 3D face animation."""

__version__ = "0.1.0"
