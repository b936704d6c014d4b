"""Focal-length self-calibration from fundamental matrices (thesis chapter 4).

- :mod:`recon.calibration.kruppa`: one pair, the degenerated Kruppa equations (4.12)-(4.14),
  with a status and a conditioning score per pair.
- :mod:`recon.calibration.fusion`: one focal (with an uncertainty) from many pairs.

Both are pure numpy: no I/O, no COLMAP.
"""

from recon.calibration.fusion import (
    FocalEstimate,
    FusionConfig,
    FusionMethod,
    FusionStatus,
    JointLoss,
    estimate_focal_joint,
    fuse_pair_focals,
)
from recon.calibration.kruppa import (
    KruppaConfig,
    KruppaMethod,
    PairFocal,
    PairStatus,
    focal_from_fundamental,
)

__all__ = [
    "FocalEstimate",
    "FusionConfig",
    "FusionMethod",
    "FusionStatus",
    "JointLoss",
    "KruppaConfig",
    "KruppaMethod",
    "PairFocal",
    "PairStatus",
    "estimate_focal_joint",
    "focal_from_fundamental",
    "fuse_pair_focals",
]
