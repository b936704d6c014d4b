"""Built-in mesh backends (plugin kind ``mesh``).

Registered in ``pyproject.toml`` under ``mocap.mesh`` like any third-party plugin. The work is
in :mod:`recon.mesh.meshing`; these classes adapt it to the plugin Protocol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from plugins.protocols import Plugin

MIN_POISSON_DEPTH = 1
MAX_POISSON_DEPTH = 13
"""Bounds of the Poisson octree depth. Depth d solves on a grid of at most 2^d cells a side: 13
is 8192, 0.24 mm cells on a 2 m person, finer than any cloud from photos. Memory and time
roughly double with each level whatever the cloud (measured on the 140,000-point cloud of the
six-photo test scene, one thread: depth 10 0.46 GB 21 s, 12 0.90 GB 41 s, 13 1.8 GB 82 s,
14 2.8 GB; the mesh stopped gaining faces at 10), and depth 40 ran out of memory (issue 23)."""


class PoissonBackend(Plugin):
    description = "screened Poisson surface (Open3D), trimmed where the cloud gives no support"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        depth: int = field(default=9, metadata={
            "help": f"octree depth (detail vs. time), {MIN_POISSON_DEPTH}-{MAX_POISSON_DEPTH}: "
                    "each +1 doubles memory"})
        max_distance_factor: float = field(
            default=3.0, metadata={"help": "remove faces farther than this many point spacings "
                                   "from the cloud, >= 0 (0: keep all)"})
        density_quantile: float = field(
            default=0.01, metadata={"help": "also trim vertices below this quantile of Poisson "
                                    "density (low support), in [0, 1); keep it small, it can "
                                    "open holes in closed surfaces"})

        def __post_init__(self) -> None:
            if not MIN_POISSON_DEPTH <= self.depth <= MAX_POISSON_DEPTH:
                raise ValueError(
                    f"depth must be in {MIN_POISSON_DEPTH}..{MAX_POISSON_DEPTH} (each level "
                    f"doubles memory; depth 13 took 1.8 GB on a 140,000-point cloud), got "
                    f"{self.depth}")
            if not (math.isfinite(self.max_distance_factor) and self.max_distance_factor >= 0):
                raise ValueError("max_distance_factor must be >= 0 and finite, got "
                                 f"{self.max_distance_factor}")
            if not 0 <= self.density_quantile < 1:  # NaN fails too
                raise ValueError(
                    f"density_quantile must be in [0, 1), got {self.density_quantile}")

    def mesh(self, cloud: Any) -> Any:
        from recon.mesh.meshing import PoissonConfig, poisson_mesh

        return poisson_mesh(cloud, PoissonConfig(
            depth=self.options.depth, max_distance_factor=self.options.max_distance_factor,
            density_quantile=self.options.density_quantile))


class BallPivotingBackend(Plugin):
    description = "ball pivoting (Open3D): interpolates the points, no hole filling"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        pass

    def mesh(self, cloud: Any) -> Any:
        from recon.mesh.meshing import BallPivotingConfig, ball_pivoting_mesh

        return ball_pivoting_mesh(cloud, BallPivotingConfig())
