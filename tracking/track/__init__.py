"""Silhouette tracking (thesis 6.2.3-6.2.5): renderers, XOR energy, the hierarchical tracker."""
