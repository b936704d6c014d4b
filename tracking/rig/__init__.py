"""The camera rig: calibrated cameras, their readers, video workspaces, synthetic sequences."""
