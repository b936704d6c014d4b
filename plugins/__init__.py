"""Plugin kinds, their Protocols and the entry-point registry.

Every extension point of the pipeline is a *kind* (for example ``intrinsics``). A kind is one
Protocol in :mod:`plugins.protocols` and one entry-point group (``mocap.<kind>``; the
subcommands of ``mocap`` are ``mocap.commands``, the steps of ``mocap batch`` ``mocap.steps``).
Built-in plugins are declared in this project's ``pyproject.toml`` exactly as a third-party
package declares its own, so there is a single loading path for both.
"""

from plugins.protocols import (
    BaseBatchStep,
    BatchStep,
    CameraInfo,
    Command,
    DenseBackend,
    DenseContext,
    DenseResult,
    FocalPrior,
    IntrinsicInitialiser,
    IntrinsicsContext,
    IntrinsicsResult,
    MeshBackend,
    Plugin,
    StepResult,
)
from plugins.registry import KINDS, PluginError, PluginInfo, available, create, list_plugins

__all__ = [
    "KINDS",
    "BaseBatchStep",
    "BatchStep",
    "CameraInfo",
    "Command",
    "DenseBackend",
    "DenseContext",
    "DenseResult",
    "FocalPrior",
    "IntrinsicInitialiser",
    "IntrinsicsContext",
    "IntrinsicsResult",
    "MeshBackend",
    "Plugin",
    "PluginError",
    "PluginInfo",
    "StepResult",
    "available",
    "create",
    "list_plugins",
]
