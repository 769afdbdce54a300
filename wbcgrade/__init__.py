"""wbcgrade: colour grading with Wasserstein barycentric coordinates."""

__version__ = "0.1.0"
