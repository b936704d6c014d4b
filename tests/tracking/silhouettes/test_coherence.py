"""The cameras' correction by silhouette coherence (`tracking.silhouettes.coherence`) on a
rendered body whose calibration is known exactly."""

from __future__ import annotations

import numpy as np
import pytest

from recon.errors import UserError
from tracking.body.model import BodyModel, BodyShape
from tracking.body.synthetic import walking_poses
from tracking.rig.cameras import ring_cameras
from tracking.silhouettes.coherence import CoherenceConfig, refine_rig, shifted
from tracking.track.render import CpuRasterRenderer

CAMERAS = ring_cameras(4, 3.0, 1.0, width=320, height=240, focal_px=300.0)


@pytest.fixture(scope="module")
def masks() -> list[list[np.ndarray]]:
    """A walking body (the thesis' superquadrics: any surface will do) in 4 frames, drawn
    with the exact cameras."""
    model = BodyModel(BodyShape.default(1.75))
    render = CpuRasterRenderer(CpuRasterRenderer.Options())
    poses = walking_poses(20, 30.0, model.shape, start_in_world=(0.0, 0.0))[::5]
    return [[render.render(model.posed_vertices(p), model.faces, c) for c in CAMERAS]
            for p in poses]  # fmt: skip


def test_a_camera_turned_off_its_calibration_is_corrected(masks):
    """Camera 1's calibration 8 px right and 6 px up of where it looks: the correction moves
    its image back (up to what a move of the subject explains) and the views agree again on
    the checking frames; the exact rig is left as it is."""
    config = CoherenceConfig(coherence_frames=4)
    exact = refine_rig(CAMERAS, masks, config=config)
    assert not exact.accepted or np.abs(exact.shifts_px).max() <= 2, exact.summary()
    off = list(CAMERAS)
    off[1] = shifted(CAMERAS[1], (8.0, -6.0))
    result = refine_rig(off, masks, config=config)
    assert result.accepted, result.summary()
    before, after = result.checked
    assert after > before + 0.02
    assert after > exact.checked[0] - 0.01  # as coherent as the exact rig
    # The image of camera 1 goes back by most of the error; the others move less.
    dx, dy = result.shifts_px[1]
    assert dx <= -4 and dy >= 2, result.summary()
    others = np.delete(result.shifts_px, 1, axis=0)
    assert np.abs(others).max() < np.abs(result.shifts_px[1]).max()
    np.testing.assert_allclose(result.cameras[1].K[:2, 2], off[1].K[:2, 2] + [dx, dy])


def test_bad_coherence_settings_are_one_line_errors():
    with pytest.raises(UserError, match="--coherence-frames"):
        CoherenceConfig(coherence_frames=1)
    with pytest.raises(UserError, match="--coherence-max-shift-px"):
        CoherenceConfig(coherence_max_shift_px=0.0)
