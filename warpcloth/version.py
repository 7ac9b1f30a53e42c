"""warpcloth's version, importable without Warp (``warpcloth --version`` and the provenance records)."""

__version__ = "0.1.0"
