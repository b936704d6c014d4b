"""Built-in mesh backends (plugin kind ``mesh``).

Registered in ``pyproject.toml`` under ``mocap.mesh`` like any third-party plugin. The work is
in :mod:`recon.mesh.meshing`; these classes adapt it to the plugin Protocol.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from plugins.protocols import Plugin


class PoissonBackend(Plugin):
    description = "screened Poisson surface (Open3D), trimmed where the cloud gives no support"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        depth: int = field(default=9, metadata={"help": "octree depth (detail vs. time)"})
        max_distance_factor: float = field(
            default=3.0, metadata={"help": "remove faces farther than this many point spacings "
                                   "from the cloud (0: keep all)"})
        density_quantile: float = field(
            default=0.01, metadata={"help": "also trim vertices below this quantile of Poisson "
                                    "density (low support); keep it small, it can open holes "
                                    "in closed surfaces"})

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
