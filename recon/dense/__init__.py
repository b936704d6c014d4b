"""CPU dense reconstruction (the "cpu-stereo" backend): rectified two-view stereo, then fusion.

:mod:`recon.dense.stereo` selects stereo pairs, computes a depth map per view and pair with
OpenCV's semi-global matcher, and back-projects depth maps to coloured points;
:mod:`recon.dense.fusion` keeps points on which several views agree and builds an Open3D point
cloud with normals facing the cameras. Pure computation: no file I/O.
"""
