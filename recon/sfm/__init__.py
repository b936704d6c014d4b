"""Structure from motion: photos, features and matches, mapping and bundle adjustment."""
