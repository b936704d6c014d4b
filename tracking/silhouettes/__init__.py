"""Silhouettes (thesis 6.2.1): background models, subtraction, the multi-view hull check."""
