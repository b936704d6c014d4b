"""Photo workspace → COLMAP sparse model → dense cloud → mesh; calibration and evaluation."""

__version__ = "0.1.0"
