"""Body model, silhouettes, renderers, the silhouette-tracking optimiser and motion reports."""
