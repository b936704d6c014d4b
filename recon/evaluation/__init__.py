"""Scoring against truth: ground-truth cameras, pose and surface errors, the synthetic room."""
