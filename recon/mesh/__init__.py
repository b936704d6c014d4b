"""Meshing: an oriented dense cloud → a cleaned, coloured triangle mesh (PLY, OBJ, GLB)."""
