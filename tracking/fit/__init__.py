"""Fitting the body model to a human point cloud (thesis ch. 5): the `mocap fit` step."""
