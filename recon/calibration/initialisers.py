"""Built-in intrinsic initialisers (plugin kind ``intrinsics``).

Each returns a focal prior per camera; the pipeline writes it into the database
(:func:`recon.sfm.pipeline.initialise_intrinsics`). They are registered in ``pyproject.toml`` under
``mocap.intrinsics`` like any third-party plugin.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from plugins.protocols import FocalPrior, IntrinsicsContext, IntrinsicsResult, Plugin
from recon.errors import UserError
from recon.sfm.images import exif_focal_px


class ColmapDefaultInitialiser(Plugin):
    """COLMAP's behaviour: no prior, start from 1.2·max(w, h), refine in bundle adjustment."""

    description = "COLMAP's default: start from 1.2·max(w, h) px, refined by bundle adjustment"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        pass

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult:
        return IntrinsicsResult(
            priors=tuple(
                FocalPrior(camera_id=c.camera_id, focal_px=None, source="1.2·max(w, h)")
                for c in context.cameras
            ),
            refine_focal=True,
        )


class ExifInitialiser(Plugin):
    """Focal from EXIF: focal length with the focal-plane resolution, or the 35 mm equivalent."""

    description = "focal from EXIF (focal length and sensor resolution, or 35 mm equivalent)"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        refine: bool = field(
            default=True, metadata={"help": "let bundle adjustment refine the EXIF focal"}
        )

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult:
        priors = []
        for camera in context.cameras:
            # All images of one camera share intrinsics; the first with EXIF speaks for them.
            found = None
            for name in camera.image_names:
                found = exif_focal_px(context.images_dir / name)
                if found is not None:
                    break
            if found is None:
                raise UserError(
                    f"exif: no EXIF focal length in {context.images_dir / camera.image_names[0]}"
                    f" (camera {camera.camera_id}); use --intrinsics colmap-default, or fixed"
                    " with -O focal_px=..."
                )
            priors.append(
                FocalPrior(camera_id=camera.camera_id, focal_px=found.focal_px, source=found.source)
            )
        return IntrinsicsResult(priors=tuple(priors), refine_focal=self.options.refine)


class FixedInitialiser(Plugin):
    """A focal length the user knows, in pixels, for every camera."""

    description = "a focal length you give in pixels (-O focal_px=...), held fixed by default"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        focal_px: float = field(metadata={"help": "focal length in pixels, for every camera"})
        refine: bool = field(
            default=False, metadata={"help": "let bundle adjustment refine the given focal"}
        )

        def __post_init__(self) -> None:
            if not self.focal_px > 0:
                raise ValueError(f"focal_px must be positive, got {self.focal_px}")

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult:
        return IntrinsicsResult(
            priors=tuple(
                FocalPrior(
                    camera_id=c.camera_id,
                    focal_px=self.options.focal_px,
                    source=f"given: {self.options.focal_px:g} px",
                )
                for c in context.cameras
            ),
            refine_focal=self.options.refine,
        )
