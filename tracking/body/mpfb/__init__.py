"""A realistic skinned human body from MakeHuman / MPFB2's CC0 assets: `convert` packs them into
one npz (package data), `model` shapes (macro targets) and poses (linear blend skinning) it with
numpy only."""
