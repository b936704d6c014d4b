"""Video workspaces (`mocap init-video`): synthetic videos with known content, bad inputs, and
the Pose2Sim demo."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from recon.cameras import Camera, write_cameras_json
from recon.cli import main
from recon.errors import UserError
from recon.workspace import Workspace
from tests.helpers import run_cli, shared_dataset
from tracking.rig.cameras import read_cameras, ring_cameras
from tracking.rig.video import init_video, match_videos, read_frames, video_info

WIDTH, HEIGHT, FRAMES = 200, 150, 24


def background_image(seed: int, width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    """A static textured scene: blurred colour noise over a gradient, grey levels 40-210."""
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.uniform(0, 255, (height, width, 3)).astype(np.float32),
                             (0, 0), 2.0)
    ramp = np.linspace(0, 60, width, dtype=np.float32)[None, :, None]
    image = 40 + 0.45 * noise + ramp
    return np.clip(image, 0, 255).astype(np.uint8)


def blob_mask(frame: int, camera: int, width: int = WIDTH, height: int = HEIGHT,
              frames: int = FRAMES) -> np.ndarray:
    """(H, W) bool truth: an ellipse (radii 26 x 34 px) crossing the view from left to right,
    wholly outside it in the first two and last two frames, at a height that depends on the
    camera."""
    # Centre x from -40 (out of view) to width + 40 (out again) over the sequence.
    cx = -40 + (width + 80) * frame / (frames - 1)
    cy = height / 2 + (camera - 1) * 12
    mask = np.zeros((height, width), np.uint8)
    cv2.ellipse(mask, (round(cx), round(cy)), (26, 34), 0, 0, 360, 1, -1, cv2.LINE_8)
    return mask.astype(bool)


def write_video(path: Path, frames: list[np.ndarray], fps: float = 25.0) -> None:
    fourcc = "MJPG" if path.suffix == ".avi" else "mp4v"
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (width, height))
    assert writer.isOpened(), f"OpenCV cannot write {fourcc} here"
    if fourcc == "MJPG":
        writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    for frame in frames:
        writer.write(frame)
    writer.release()


def make_blob_scene(folder: Path, cameras: int = 3, frames: int = FRAMES,
                    suffixes: tuple[str, ...] = (".avi", ".mp4", ".avi")
                    ) -> tuple[Path, Path, list[list[np.ndarray]]]:  # fmt: skip
    """Videos ``folder/videos/cam0k.<ext>`` of a static textured background and an orange blob
    with known masks, and a matching JSON calibration; returns (videos dir, calibration,
    truth masks per camera per frame)."""
    videos = folder / "videos"
    videos.mkdir(parents=True)
    truth = []
    for k in range(cameras):
        background = background_image(seed=k)
        masks = [blob_mask(i, k, frames=frames) for i in range(frames)]
        images = []
        for mask in masks:
            image = background.copy()
            image[mask] = (30, 140, 250)  # orange (BGR): far from the background in blue
            images.append(image)
        write_video(videos / f"cam{k:02d}{suffixes[k % len(suffixes)]}", images)
        truth.append(masks)
    calibration = folder / "cameras.json"
    write_cameras_json(calibration, ring_cameras(cameras, 3.0, 1.5, width=WIDTH, height=HEIGHT,
                                                 focal_px=220.0))
    return videos, calibration, truth


def ball_masks(cameras: list[Camera], centre: np.ndarray, radius: float) -> list[np.ndarray]:
    """(H, W) bool truth per camera: the pixels whose ray meets a ball (world centre, metres)."""
    masks = []
    for cam in cameras:
        c = cam.R @ centre + cam.t
        rays = cam.pixel_rays_in_camera / np.linalg.norm(cam.pixel_rays_in_camera, axis=2,
                                                         keepdims=True)
        along = rays @ c
        masks.append((along > 0) & (c @ c - along**2 < radius**2))
    return masks


def make_ball_scene(folder: Path, cameras: int = 4, frames: int = FRAMES
                    ) -> tuple[Path, Path, Path, list[list[np.ndarray]]]:  # fmt: skip
    """A subject that stays put: an orange ball of 0.35 m wobbling by 0.15 m about the target
    of a ring of cameras (3 m away, 1.5 m up), so that its core is covered in every frame, as
    the torso of a person balancing on one spot is. In cam00's video a light flashes on a wall
    below the ball in every third frame (what one camera alone sees). Writes the videos, their
    calibration and a background photo per camera (``photos/cam0k_ext.png``: the empty scene
    5% darker, and in cam00's a foreign blue block next to the ball, which the video never
    shows). Returns (videos dir, calibration, photos dir, truth masks per camera per frame)."""
    rigs = ring_cameras(cameras, 3.0, 1.5, width=WIDTH, height=HEIGHT, focal_px=220.0)
    videos, photos = folder / "videos", folder / "photos"
    videos.mkdir(parents=True)
    photos.mkdir()
    truth: list[list[np.ndarray]] = [[] for _ in rigs]
    for i in range(frames):
        a = 2 * np.pi * i / frames
        centre = np.array([0.15 * np.cos(3 * a), 0.1 * np.sin(2 * a), 0.15 * np.sin(3 * a)])
        for k, mask in enumerate(ball_masks(rigs, centre, 0.35)):
            truth[k].append(mask)
    middle = np.array([WIDTH / 2, HEIGHT / 2]).astype(int)
    for k in range(len(rigs)):
        background = background_image(seed=k)
        images = []
        for i, mask in enumerate(truth[k]):
            image = background.copy()
            if k == 0 and i % 3 == 0:
                image[HEIGHT - 25:HEIGHT - 5, 20:60] = 245
            image[mask] = (30, 140, 250)
            images.append(image)
        write_video(videos / f"cam{k:02d}.avi", images)
        photo = (background.astype(np.float32) * 0.95).astype(np.uint8)
        if k == 0:
            x, y = middle
            photo[y - 30:y + 30, x + 24:x + 40] = (200, 60, 20)
        cv2.imwrite(str(photos / f"cam{k:02d}_ext.png"), photo)
    calibration = folder / "cameras.json"
    write_cameras_json(calibration, rigs)
    return videos, calibration, photos, truth


def digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, list]:
    return make_blob_scene(tmp_path_factory.mktemp("blob"))


def cli_error(capsys: pytest.CaptureFixture[str], *args: str | Path) -> str:
    """Run `mocap ARGS` in-process; assert exit code 2 and one line on stderr; return it."""
    assert main([str(a) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


# ---------------------------------------------------------------------------------------------


def test_init_video_links_the_videos_and_writes_the_cameras(scene, tmp_path: Path):
    videos, calibration, _ = scene
    before = digest(videos)
    ws = init_video(tmp_path / "ws", videos, calibration)
    assert digest(videos) == before  # inputs untouched
    assert sorted(p.name for p in ws.videos_dir.iterdir()) == ["cam00.avi", "cam01.mp4",
                                                               "cam02.avi"]
    for p in ws.videos_dir.iterdir():  # same bytes as the input (a link or a copy)
        assert hashlib.sha256(p.read_bytes()).hexdigest() == before[p.name]
    assert read_cameras(ws.cameras_path) == read_cameras(calibration)
    assert Workspace.open_video(ws.root).root == ws.root
    summary = ws.step("init-video").summary
    assert summary["frames"] == FRAMES and summary["fps"] == pytest.approx(25.0)
    assert summary["cameras"]["cam01"]["content_box"] == [0, 0, WIDTH, HEIGHT]
    assert video_info(ws.videos_dir / "cam01.mp4") == (FRAMES, WIDTH, HEIGHT, pytest.approx(25))

    # Frames come back in index order, the requested ones only, equal to a direct decode.
    got = list(read_frames(ws, "cam00", [7, 3, 3, 20]))
    assert [i for i, _ in got] == [3, 7, 20]
    capture = cv2.VideoCapture(str(videos / "cam00.avi"))
    direct = [capture.read()[1] for _ in range(8)]
    np.testing.assert_array_equal(got[1][1], direct[7])
    assert sum(1 for _ in read_frames(ws, "cam02")) == FRAMES
    with pytest.raises(UserError, match="ends after 24 frames; frame 30"):
        list(read_frames(ws, "cam00", [2, 30]))

    # Same inputs: reused as they are; other inputs: refused without --overwrite.
    stamp = ws.cameras_path.stat().st_mtime_ns
    assert init_video(tmp_path / "ws", videos, calibration).root == ws.root
    assert ws.cameras_path.stat().st_mtime_ns == stamp
    other = tmp_path / "other.json"
    write_cameras_json(other, ring_cameras(3, 4.0, 1.5, width=WIDTH, height=HEIGHT))
    with pytest.raises(UserError, match="already holds other videos or cameras"):
        init_video(tmp_path / "ws", videos, other)
    (ws.silhouettes_dir / "cam00").mkdir(parents=True)
    init_video(tmp_path / "ws", videos, other, overwrite=True)
    assert read_cameras(ws.cameras_path)[0].center_in_world[2] == pytest.approx(4.0)
    assert not ws.silhouettes_dir.exists()  # derived from the old inputs


def test_cameras_and_videos_pair_by_name_or_by_number_order(tmp_path: Path):
    cams = ring_cameras(3, 3.0, 1.5)
    renamed = [Camera(n, c.width, c.height, c.K, c.cam_from_world)
               for n, c in zip(["Left", "right", "top"], cams, strict=True)]
    videos = [tmp_path / n for n in ("RIGHT.mp4", "left.avi", "Top.mov")]
    assert [(c.name, p.name) for c, p in match_videos(renamed, videos)] == [
        ("Left", "left.avi"), ("right", "RIGHT.mp4"), ("top", "Top.mov")]
    # Pose2Sim's order: cam2 before cam10, whatever the names say.
    numbered = [tmp_path / n for n in ("cam10.mp4", "cam2.mp4", "cam1.mp4")]
    assert [(c.name, p.name) for c, p in match_videos(cams, numbered, "order")] == [
        ("cam00", "cam1.mp4"), ("cam01", "cam2.mp4"), ("cam02", "cam10.mp4")]
    with pytest.raises(UserError) as error:
        match_videos(cams, numbered)
    message = str(error.value)
    assert "no video for camera(s) cam00, cam01, cam02" in message
    assert "no camera for video(s) cam1.mp4, cam10.mp4, cam2.mp4" in message
    assert "--match order" in message
    # Pose2Sim's Calib.toml names cameras cam_01...: separators and case do not count.
    underscored = [Camera(f"cam_0{k}", c.width, c.height, c.K, c.cam_from_world)
                   for k, c in enumerate(cams, start=1)]
    videos = [tmp_path / n for n in ("CAM01.mp4", "cam-02.mp4", "cam03.mp4")]
    assert [(c.name, p.name) for c, p in match_videos(underscored, videos)] == [
        ("cam_01", "CAM01.mp4"), ("cam_02", "cam-02.mp4"), ("cam_03", "cam03.mp4")]
    with pytest.raises(UserError, match="differ only in case or separators"):
        match_videos([underscored[0], Camera("cam01", 640, 480, cams[0].K,
                                             cams[0].cam_from_world)], videos[:2])


def test_bad_inputs_get_one_line_and_exit_code_2(scene, tmp_path: Path, capsys):
    videos, calibration, _ = scene
    ws = tmp_path / "ws"

    # Names that do not pair up: both sides listed.
    renamed = tmp_path / "renamed"
    renamed.mkdir()
    for p in videos.iterdir():
        (renamed / p.name.replace("cam02", "side")).write_bytes(p.read_bytes())
    err = cli_error(capsys, "init-video", ws, "--videos", renamed, "--calibration", calibration)
    assert "no video for camera(s) cam02" in err and "no camera for video(s) side.avi" in err

    # Different frame counts: every count listed.
    short = tmp_path / "short"
    short.mkdir()
    for p in videos.iterdir():
        (short / p.name).write_bytes(p.read_bytes())
    write_video(short / "cam01.mp4", [background_image(1)] * (FRAMES - 4))
    err = cli_error(capsys, "init-video", ws, "--videos", short, "--calibration", calibration)
    assert "different frame counts" in err and "cam01.mp4 20" in err and "cam00.avi 24" in err

    # A calibration for another image size: both sizes named.
    wrong = tmp_path / "wrong.json"
    write_cameras_json(wrong, ring_cameras(3, 3.0, 1.5, width=WIDTH + 40, height=HEIGHT))
    err = cli_error(capsys, "init-video", ws, "--videos", videos, "--calibration", wrong)
    assert f"is {WIDTH}x{HEIGHT} but wrong.json calibrates {WIDTH + 40}x{HEIGHT}" in err

    # One camera is not enough; a missing folder and a broken calibration are named.
    one = tmp_path / "one.json"
    write_cameras_json(one, ring_cameras(1, 3.0, 1.5, width=WIDTH, height=HEIGHT))
    single = tmp_path / "single"
    single.mkdir()
    (single / "cam00.avi").write_bytes((videos / "cam00.avi").read_bytes())
    assert "at least 2 cameras" in cli_error(capsys, "init-video", ws, "--videos", single,
                                             "--calibration", one)
    assert "does not exist" in cli_error(capsys, "init-video", ws, "--videos",
                                         tmp_path / "nowhere", "--calibration", calibration)
    broken = tmp_path / "broken.json"
    broken.write_text("{}")
    assert "broken.json" in cli_error(capsys, "init-video", ws, "--videos", videos,
                                      "--calibration", broken)
    # A truncated video is named, in one line: run as a subprocess, since FFmpeg would write
    # its own complaint to the process's stderr, which capsys does not see.
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    for p in videos.iterdir():
        (corrupt / p.name).write_bytes(p.read_bytes()[:200] if p.name == "cam01.mp4"
                                       else p.read_bytes())
    result = run_cli("init-video", ws, "--videos", corrupt, "--calibration", calibration)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "cannot open video" in result.stderr and "cam01.mp4" in result.stderr
    assert not ws.exists()  # nothing was written by any of them


def test_a_letterboxed_video_gets_its_camera_adjusted(tmp_path: Path, capsys):
    """Calibrated 200x150, recorded as 200x160 with 5 black rows above and below (scale 1):
    accepted, with the principal point moved down 5 px; without the bars it is refused."""
    cams = ring_cameras(2, 3.0, 1.5, width=WIDTH, height=HEIGHT, focal_px=220.0)
    calibration = tmp_path / "cams.json"
    write_cameras_json(calibration, cams)
    boxed, plain = tmp_path / "boxed", tmp_path / "plain"
    boxed.mkdir()
    plain.mkdir()
    for k, cam in enumerate(cams):
        image = background_image(k)
        frame = np.zeros((HEIGHT + 10, WIDTH, 3), np.uint8)
        frame[5:5 + HEIGHT] = image
        write_video(boxed / f"{cam.name}.avi", [frame] * 4)
        write_video(plain / f"{cam.name}.avi", [cv2.resize(image, (WIDTH, HEIGHT + 10))] * 4)
    ws = init_video(tmp_path / "ws", boxed, calibration)
    written = read_cameras(ws.cameras_path)
    assert (written[0].width, written[0].height) == (WIDTH, HEIGHT + 10)
    np.testing.assert_allclose(written[0].K, cams[0].K + [[0, 0, 0], [0, 0, 5.0], [0, 0, 0]])
    np.testing.assert_array_equal(written[1].cam_from_world, cams[1].cam_from_world)
    summary = ws.step("init-video").summary
    assert summary["cameras"]["cam00"]["content_box"] == [0, 5, WIDTH, HEIGHT + 5]
    assert "black bars of 5.00 px top and bottom" in summary["notes"][0]
    err = cli_error(capsys, "init-video", tmp_path / "ws2", "--videos", plain,
                    "--calibration", calibration)
    assert f"{WIDTH}x{HEIGHT + 10} but cams.json calibrates {WIDTH}x{HEIGHT}" in err


@pytest.mark.shared_data
def test_init_video_on_the_pose2sim_demo(tmp_path: Path):
    demo = shared_dataset("pose2sim_demo")
    calibration = demo / "calibration" / "Calib.qca.txt"
    ws = init_video(tmp_path / "ws", demo / "videos", calibration)
    summary = ws.step("init-video").summary
    assert summary["frames"] == 100 and summary["fps"] == pytest.approx(60.0)
    cams = {c.name: c for c in read_cameras(ws.cameras_path)}
    calibrated = {c.name: c for c in read_cameras(calibration)}
    assert list(cams) == ["cam01", "cam02", "cam03", "cam04"]
    # cam03/04 are recorded at the calibrated 1088x1920 and kept as they are; cam01/02 are
    # 1080x1920: the calibrated image scaled by 1080/1088 between 7-px black bars.
    assert cams["cam03"] == calibrated["cam03"]
    s = 1080 / 1088
    for name in ("cam01", "cam02"):
        cam, cal = cams[name], calibrated[name]
        assert (cam.width, cam.height) == (1080, 1920)
        assert cam.K[0, 0] == pytest.approx(s * cal.K[0, 0])
        assert cam.K[1, 2] == pytest.approx(s * cal.K[1, 2] + (1920 - s * 1920) / 2)
        assert summary["cameras"][name]["content_box"] == [0, 8, 1080, 1912]
    # The camera model agrees with the picture: the top bar is black, the row below is not.
    _, frame = next(read_frames(ws, "cam01", [0]))
    assert frame[:7].mean() < 10 and frame[8].mean() > 60
    run = json.loads(ws.run_json.read_text())
    assert run["steps"]["init-video"]["config"]["match"] == "name"
