"""gearsym: planetary automatic transmission → validated symbolic model → TCU code."""

__version__ = "0.1.0"
