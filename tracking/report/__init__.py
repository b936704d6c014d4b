"""Motion reports: segment parameters, kinematics, joint angles and inverse dynamics."""
