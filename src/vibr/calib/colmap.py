"""Camera calibration from raw photos with COLMAP (pycolmap), CPU only.

Pipeline (``vibr calibrate PHOTOS_DIR OUT_SCENE``)
--------------------------------------------------
0. From a **video** (``vibr calibrate VIDEO OUT_SCENE``): the sharpest frame of each of
   ``frames`` equal stretches becomes a photo (:mod:`vibr.calib.video_frames`), and matching is
   sequential by default.
1. **Downscale** every photo by ``scale`` (Lanczos) into a work folder, as PNG (lossless).
2. **Features**: SIFT extraction (``pycolmap.extract_features``), one shared camera by
   default (photos from one camera), camera model ``SIMPLE_RADIAL`` by default.
3. **Matching**: exhaustive (all pairs; best for ≲ 100 photos) or sequential (neighbours in
   file-name order; for video-like captures), with two-view geometric verification.
4. **Incremental mapping** (``pycolmap.incremental_mapping``): poses, intrinsics and sparse
   points by bundle adjustment; the largest model is kept. Then, by default, the principal
   point is refined by one more bundle adjustment and kept only if its covariance shows
   the photos determine it (:func:`_refine_principal_point`).
5. **Undistortion** to PINHOLE cameras (``pycolmap.undistort_images``).
6. A :class:`~vibr.scene.Scene` in vibr's conventions: ``x̃ = K (R X + t)`` with
   ``R, t = cam_from_world`` (COLMAP's pose is already world → camera) and the principal
   point shifted by −½ px (COLMAP puts the centre of the top-left pixel at (½, ½), vibr at
   (0, 0); see :mod:`vibr.camera`). The sparse points go to ``scene.points`` (they bound the
   depth range of the plane sweep, ``Scene.depth_range``), and the scene is written with
   :func:`vibr.io.save_scene` into a temporary sibling of ``out_dir`` that is renamed at the
   end, so a failed run leaves no partial output.

The reconstruction's scale and world frame are arbitrary (COLMAP's gauge): depth maps and
renders made from it are consistent with it. :func:`similarity_align`,
:func:`align_cameras` and :func:`pose_errors` compare it to reference cameras up to that similarity.
"""

from __future__ import annotations

import contextlib
import json
import logging
import shutil
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .._runtime.pycolmap import import_pycolmap
from ..camera import Camera
from ..errors import OutputExists, VibrInputError
from ..io.images import IMAGE_EXTS, image_size
from ..io.outputs import check_not_input, check_replaceable
from ..io.video import VIDEO_INPUTS, is_video_input
from ..progress import progress
from ..scene import Scene, View
from .pan import Choice, fit_one_centre, focal_note, prefer_one_centre
from .video_frames import DEFAULT_FRAMES, extract_frames

logger = logging.getLogger(__name__)

#: Photo file extensions read by calibrate (case-insensitive): the ones every loader reads.
IMAGE_EXTENSIONS = IMAGE_EXTS

#: Default minimum number of registered images (two sources and a target to render).
MIN_REGISTERED = 3

CAMERA_MODELS = ("SIMPLE_RADIAL", "RADIAL", "OPENCV", "SIMPLE_PINHOLE", "PINHOLE")
MATCHERS = ("exhaustive", "sequential")


@dataclass
class CalibrationReport:
    """What a calibration did: registered / unregistered image names, counts, stage times (s)."""

    registered: list[str]
    unregistered: list[str]
    num_points: int
    mean_reprojection_error_px: float
    image_size: tuple[int, int]
    times_s: dict[str, float]

    def summary(self) -> str:
        t = ", ".join(f"{k} {v:.1f}s" for k, v in self.times_s.items())
        lines = [
            f"registered {len(self.registered)}/{len(self.registered) + len(self.unregistered)} images, "
            f"{self.num_points} sparse points, mean reprojection error "
            f"{self.mean_reprojection_error_px:.3f} px",
            f"time: {t}",
        ]
        return "\n".join(lines)  # the photos left out: a warning at the mapping stage


# ---------------------------------------------------------------------------- inputs
def list_photos(photos_dir) -> list[Path]:
    """The photos in ``photos_dir`` (not recursive), sorted by name.

    Raises :class:`VibrInputError` if the folder does not exist, holds no image files, or
    two files share a stem (vibr names views by stem).
    """
    d = Path(photos_dir)
    if not d.exists():
        raise VibrInputError(("video" if d.suffix.lower() in VIDEO_INPUTS else "photo folder") + " not found", d)
    if not d.is_dir():
        raise VibrInputError("not a folder of photos nor a video (calibrate reads a folder of photos, "
                             f"or a video: {', '.join(VIDEO_INPUTS)})", d)
    files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS)
    videos = sorted(p.name for p in d.iterdir() if p.is_file() and p.suffix.lower() in VIDEO_INPUTS)
    if not files:
        heic = any(p.suffix.lower() in (".heic", ".heif") for p in d.iterdir())
        raise VibrInputError(
            f"no photos found (looked for {', '.join(IMAGE_EXTENSIONS)})"
            + ("; HEIC photos (a phone's default) need converting to JPEG first" if heic else "")
            + (f"; for the video, 'vibr calibrate {d / videos[0]} OUT'" if videos else ""), d
        )
    if videos:  # a phone's folder holds both: the photos are calibrated, the video is not mixed in
        logger.info(f"calibrate: {', '.join(videos[:3])}{', ...' if len(videos) > 3 else ''} in the folder: "
                    f"not used with the photos ('vibr calibrate {videos[0]} OUT' calibrates a video's frames)")
    stems = [p.stem for p in files]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise VibrInputError(f"several photos share a name stem: {', '.join(dup)}", d)
    return files


#: The smallest photo side (pixels, after ``--scale``) SIFT is given: below it a photo yields
#: too few features to register (a 640×480 photo at --scale 0.001 was 1×0 pixels).
MIN_PHOTO_SIDE = 32


def _header_sizes(files: list[Path]) -> list[tuple[int, int]] | None:
    """(width, height) of each photo from its header, or None if one is unreadable."""

    try:
        return [image_size(f) for f in files]
    except (OSError, ValueError, VibrInputError):
        return None


def _check_photo_sides(files: list[Path], sizes, scale: float, photos_dir: Path) -> None:
    """Refuse a ``scale`` that makes a photo smaller than :data:`MIN_PHOTO_SIDE` a side."""
    (w, h), f = min(zip(sizes, files), key=lambda t: min(t[0]))
    if min(w, h) * scale < MIN_PHOTO_SIDE:
        raise VibrInputError(f"at --scale {scale:g} photo {f.name} ({w}x{h}) would be "
                             f"{round(w * scale)}x{round(h * scale)} pixels: SIFT needs at least "
                             f"{MIN_PHOTO_SIDE} a side (use a larger --scale)", photos_dir)


def _check_work_space(work: Path, sizes, opt, own_work: bool) -> None:
    """Refuse a work folder without room for the calibration: COLMAP aborts the whole process
    when its disk fills up (a C++ stack dump, no error line). The need, about: the resized
    copies and the undistorted images (PNG, taken as half their 3 bytes a pixel each) and the
    database (each photo's features, taken as half of ``max_features`` × 128 bytes)."""
    import shutil

    try:
        free = shutil.disk_usage(work).free
    except OSError:
        return
    px = sum(w * h for w, h in sizes) * opt.scale ** 2
    need = 3.0 * px + len(sizes) * opt.max_features * 64.0
    if free < need:
        where = "the temporary folder (set TMPDIR, or --work DIR on another disk)" if own_work else "--work"
        raise VibrInputError(f"{free / 2**20:.0f} MiB free, calibrating {len(sizes)} photos needs about "
                             f"{need / 2**20:.0f} MiB: free some space or choose another {where}", work)


def _downscale_photos(files: list[Path], out_dir: Path, scale: float) -> list[tuple[int, int]]:
    """Write each photo, turned upright by its EXIF orientation and resized by ``scale``
    (Lanczos), as ``out_dir/<stem>.png`` (8-bit RGB).

    Returns the list of (width, height) of the written images. The new size is
    ``round(W·s) × round(H·s)``, consistent with :meth:`vibr.camera.Camera.scaled`.
    """
    from PIL import Image, ImageOps

    out_dir.mkdir(parents=True, exist_ok=True)
    sizes = []
    for f in progress(files, desc="calibrate: downscale"):
        try:
            with Image.open(f) as im:
                im.load()
                # a phone's portrait photo is stored sideways with an EXIF orientation: the
                # scene (and COLMAP, which reads these copies) gets it as it is displayed
                im = ImageOps.exif_transpose(im)
                if im.mode not in ("RGB", "L"):
                    # 16-bit / alpha / palette → 8-bit RGB (SIFT works on 8-bit grey).
                    im = im.convert("RGB") if im.mode not in ("I;16", "I", "F") else _to8bit(im)
                w, h = im.size
                if scale != 1.0:
                    nw, nh = max(1, int(round(w * scale))), max(1, int(round(h * scale)))
                    im = im.resize((nw, nh), Image.LANCZOS)
                im.save(out_dir / f"{f.stem}.png")
                sizes.append(im.size)
        except Image.DecompressionBombError as exc:
            raise VibrInputError(_too_large(exc), f) from None
        except (OSError, ValueError) as exc:
            raise VibrInputError(f"cannot read image: {exc}", f) from None
    return sizes


def _too_large(exc) -> str:
    """The one-line message for a photo Pillow refuses to decode (its decompression-bomb
    limit): its size in megapixels and the limit, from Pillow's message."""
    import re

    n = [int(x) for x in re.findall(r"\((\d+) pixels\)|limit of (\d+)", str(exc)) for x in x if x]
    if len(n) == 2:
        return (f"image of {n[0] / 1e6:.0f} Mpixels is larger than Pillow decodes safely ({n[1] / 1e6:.0f} "
                "Mpixels): resize it first")
    return f"image is larger than Pillow decodes safely ({exc}): resize it first"


def _lens_keys(files: list[Path]) -> list[tuple | None]:
    """Each photo's camera and focal length from its EXIF header (make, model, focal length
    in mm to 0.1 mm), or None where it has none: the copies COLMAP reads are PNGs without
    EXIF, so this is what tells a zoom or a second camera apart."""
    from PIL import Image

    keys = []
    for f in files:
        try:
            with Image.open(f) as im:
                ex = im.getexif()
                focal = ex.get_ifd(0x8769).get(0x920A)  # Exif IFD: FocalLength
                key = (ex.get(0x010F), ex.get(0x0110), None if focal is None else round(float(focal), 1))
        except (OSError, ValueError, TypeError, ZeroDivisionError, Image.DecompressionBombError):
            key = None
        keys.append(None if key is None or key == (None, None, None) else key)
    return keys


def _to8bit(im):
    from PIL import Image

    a = np.asarray(im, dtype=np.float64)
    hi = a.max() if a.max() > 0 else 1.0
    return Image.fromarray(np.clip(a / hi * 255 + 0.5, 0, 255).astype(np.uint8)).convert("RGB")


@contextlib.contextmanager
def _colmap_log_level(verbose: bool):
    """Silence COLMAP's glog INFO lines unless ``verbose``."""
    pycolmap = import_pycolmap()

    old = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 0 if verbose else 2
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = old


# ---------------------------------------------------------------------------- COLMAP → vibr
def camera_from_colmap(cam, image, source=None) -> Camera:
    """vibr :class:`Camera` from a pycolmap PINHOLE / SIMPLE_PINHOLE camera and its image.

    ``K = [[fx, 0, cx − ½], [0, fy, cy − ½], [0, 0, 1]]`` (COLMAP's pixel centres are at
    half-integers, vibr's at integers); ``R, t`` = COLMAP's ``cam_from_world`` (world →
    camera, as in vibr).
    """
    model = cam.model_name if hasattr(cam, "model_name") else str(cam.model)
    p = np.asarray(cam.params, dtype=np.float64)
    if model.endswith("SIMPLE_PINHOLE"):
        fx = fy = p[0]
        cx, cy = p[1], p[2]
    elif model.endswith("PINHOLE"):
        fx, fy, cx, cy = p[:4]
    else:
        raise VibrInputError(f"camera model {model} is not a pinhole model (undistort first)", source)
    K = np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])
    pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
    R = np.asarray(pose.rotation.matrix(), dtype=np.float64)
    t = np.asarray(pose.translation, dtype=np.float64)
    # COLMAP's quaternion → matrix is orthonormal to ~1e-15; re-orthonormalise anyway (SVD).
    U, _, Vt = np.linalg.svd(R)
    R = U @ Vt
    return Camera(K, R, t, int(cam.width), int(cam.height), source)


def scene_from_reconstruction(rec, image_dir, *, name="scene", root=None, meta=None) -> Scene:
    """Scene from an undistorted pycolmap Reconstruction and its image folder.

    Views are sorted by image name; images are read as H×W×3 float32 in [0, 1]; the
    reconstruction's 3D points become ``scene.points`` ((N, 3) float64, world units).
    """
    import imageio.v3 as iio

    image_dir = Path(image_dir)
    images = sorted((im for im in rec.images.values() if _has_pose(im)), key=lambda im: im.name)
    views = []
    for im in images:
        path = image_dir / im.name
        try:
            a = iio.imread(path)
        except (OSError, ValueError) as exc:
            raise VibrInputError(f"cannot read undistorted image: {exc}", path) from None
        if a.ndim == 2:
            a = np.repeat(a[..., None], 3, axis=2)
        a = a[..., :3]
        img = a.astype(np.float32) / float(np.iinfo(a.dtype).max if a.dtype.kind in "ui" else 1.0)
        cam = camera_from_colmap(rec.cameras[im.camera_id], im, source=str(path))
        views.append(View(Path(im.name).stem, img, cam, path=str(path)))
    if rec.num_points3D():
        pts = np.array([p.xyz for p in rec.points3D.values()], dtype=np.float64).reshape(-1, 3)
    else:
        pts = np.zeros((0, 3))
    return Scene(views, name=name, root=Path(root) if root else None, points=pts, meta=dict(meta or {}))


def _has_pose(im) -> bool:
    hp = im.has_pose
    return bool(hp() if callable(hp) else hp)


# ---------------------------------------------------------------------------- options
@dataclass(frozen=True)
class CalibrateOptions:
    """How :func:`calibrate_scene` calibrates (every field has a default).

    Attributes
    ----------
    scale : float
        Resize factor applied to the photos before everything else (0 < scale ≤ 4; 0.5 of
        3072×2048 gives 1536×1024). The scene's cameras are those of the resized images.
    matcher : {"exhaustive", "sequential"}, optional
        Pair selection for feature matching; None (the default): sequential for a video
        (frames in time order; COLMAP's quadratic overlap also pairs frames 2, 4, ..., 512
        apart, which closes a loop round an object), exhaustive for photos.
    frames : int
        From a video: how many frames become photos (the sharpest of each of as many equal
        stretches; every frame when it has fewer). Ignored for a folder of photos.
    camera_model : str
        COLMAP model estimated by bundle adjustment (SIMPLE_RADIAL, RADIAL, OPENCV,
        SIMPLE_PINHOLE, PINHOLE). Distorted models are undistorted to PINHOLE in step 5.
    single_camera : bool
        One shared intrinsic camera for all photos (same camera and zoom) or one per photo.
        Photos of several sizes, or whose EXIF names several cameras or focal lengths (a
        zoom), get one camera each whatever this says.
    refine_principal_point : bool, optional
        True: bundle adjustment refines the principal point throughout the mapping.
        False: it stays at the image centre (COLMAP's default). None ("auto"): map with it
        fixed, then refine it in one global bundle adjustment and keep the result only if
        its covariance shows the photos determine it (:func:`_refine_principal_point`).
        Held at the centre when it is off centre, the poses absorb the offset as a small
        common rotation of every camera (docs/explanation/calibration.md).
    pan : bool, optional
        Photographs turned on the spot (a panorama, a video panned from one place): one
        centre for every camera, rotations and intrinsics fitted to the tracks without the
        mapper's translations (:mod:`vibr.calib.pan`). None ("auto", the default):
        when most image pairs are related by homographies and the mapper's model does no
        better (:func:`vibr.calib.pan.prefer_one_centre`); True: always; False: never
        (the mapper's cameras as they are).
    min_registered : int
        Fewer registered images raise :class:`VibrInputError` naming the unregistered ones.
    max_features : int
        SIFT features per image.
    num_threads : int
        Threads for COLMAP's stages (the machine is shared; default 2).
    seed : int
        Random seed for the mapper's RANSAC (reproducible runs).
    verbose : bool
        Let COLMAP print its log.
    """

    scale: float = 1.0
    matcher: str | None = None
    frames: int = DEFAULT_FRAMES
    camera_model: str = "SIMPLE_RADIAL"
    single_camera: bool = True
    refine_principal_point: bool | None = None
    pan: bool | None = None
    min_registered: int = MIN_REGISTERED
    max_features: int = 8192
    num_threads: int = 2
    seed: int = 0
    verbose: bool = False


# ---------------------------------------------------------------------------- main entry points
def calibrate_scene(photos_dir, *, options: CalibrateOptions | None = None, work_dir=None,
                    **kw) -> tuple[Scene, CalibrationReport]:
    """Calibrate a folder of photos with COLMAP; return the undistorted scene (in memory).

    Parameters
    ----------
    photos_dir : path
        Folder of photos of one static scene (jpg/png/tif...), not recursive, or a video of
        it (:data:`vibr.io.video.VIDEO_INPUTS`): the sharpest frame of each of
        ``options.frames`` stretches is calibrated (:func:`vibr.calib.video_frames.extract_frames`).
    options : CalibrateOptions, optional
        How to calibrate; ``kw`` (fields of :class:`CalibrateOptions`, e.g. ``scale=0.5``)
        applies over it. Any other keyword raises ``TypeError``.
    work_dir : path, optional
        Where to keep COLMAP's database, model and undistorted images; a temporary folder
        (removed afterwards) by default.

    Returns
    -------
    scene : Scene
        Undistorted PINHOLE views named by photo stem (sorted), ``scene.points`` the sparse
        points, ``scene.meta`` the calibration summary.
    report : CalibrationReport
    """
    pycolmap = import_pycolmap()

    opt = replace(options or CalibrateOptions(), **kw)
    photos_dir = Path(photos_dir)
    video = is_video_input(photos_dir)
    files = None if video else list_photos(photos_dir)
    opt = _check_options(opt, None if video else len(files), photos_dir)
    opt = replace(opt, matcher=opt.matcher or ("sequential" if video else "exhaustive"))
    own_work = work_dir is None
    work = Path(tempfile.mkdtemp(prefix="vibr-calibrate-")) if own_work else Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    times: dict[str, float] = {}
    frames = None
    try:
        if video:
            t0 = time.perf_counter()
            frames = extract_frames(photos_dir, work / "frames", opt.frames)
            files = _check_frames(frames, opt, photos_dir)
            times["frames"] = time.perf_counter() - t0
        sizes = _header_sizes(files)  # None when a header is unreadable: named later
        if sizes is not None:
            _check_photo_sides(files, sizes, opt.scale, photos_dir)
            _check_work_space(work, sizes, opt, own_work)
        img_dir, db, sparse, undist = _clean_work(work)
        sizes, opt = _resized_photos(files, img_dir, opt, times)
        names = [f"{f.stem}.png" for f in files]
        stem = {f"{f.stem}.png": f.name for f in files}
        with _colmap_log_level(opt.verbose):
            times["features"] = _extract_features(db, img_dir, names, sizes, opt)
            times["matching"] = _match_features(db, opt)
            t0 = time.perf_counter()
            one = _fit_one_centre(db, opt)
            if opt.pan is not False:
                times["one_centre"] = time.perf_counter() - t0
            recs, choice = _mapping_or_one_centre(one, db, img_dir, sparse, len(files), opt, times)
            taken = choice is not None and choice.one_centre
            best_key, rec, registered, unregistered = _kept_model(recs, names, stem, photos_dir, opt)
            rec, pp_note = _principal_point(rec, opt, taken, times)
            urec = _undistorted(rec, sparse / str(best_key), img_dir, undist, len(registered), opt, times)
        report = CalibrationReport(
            registered=[stem[n] for n in registered],
            unregistered=[stem[n] for n in unregistered],
            num_points=int(rec.num_points3D()),
            mean_reprojection_error_px=float(rec.compute_mean_reprojection_error()),
            image_size=tuple(max(sizes, key=lambda wh: wh[0] * wh[1])),
            times_s=times,
        )
        meta = _calibration_meta(photos_dir, opt, pp_note, report, pycolmap.__version__, frames)
        meta["calibration"]["turned_on_the_spot"] = taken
        if one is not None:
            meta["calibration"]["one_centre"] = _one_centre_summary(one, choice)
        scene = scene_from_reconstruction(
            urec, undist / "images", name=photos_dir.resolve().stem if video else photos_dir.resolve().name,
            root=None, meta=meta
        )
        return scene, report
    finally:
        if own_work:
            shutil.rmtree(work, ignore_errors=True)


def _resized_photos(files: list[Path], img_dir: Path, opt: CalibrateOptions, times: dict):
    """Step 1/5: the photos resized by ``opt.scale`` into ``img_dir``; their sizes, and
    ``opt`` with one camera per photo where one shared camera would be wrong."""
    t0 = time.perf_counter()
    logger.info(f"calibrate [1/5] resizing {len(files)} photos by {opt.scale:g}")
    sizes = _downscale_photos(files, img_dir, opt.scale)
    lenses = _lens_keys(files)
    if opt.single_camera and len(set(sizes)) > 1:
        # One shared camera needs one image size: photos of several sizes get one each.
        logger.info(f"calibrate: photos have {len(set(sizes))} different sizes: one camera per photo")
        opt = replace(opt, single_camera=False)
    elif opt.single_camera and len(set(lenses)) > 1:
        # a zoom, or a second camera of the same resolution: one focal length would be wrong
        logger.info(f"calibrate: the photos' EXIF names {len(set(lenses))} cameras or focal lengths: "
                    "one camera per photo")
        opt = replace(opt, single_camera=False)
    times["resize"] = time.perf_counter() - t0
    return sizes, opt


def _principal_point(rec, opt: CalibrateOptions, turned_on_the_spot: bool, times: dict):
    """The kept model with its principal point refined when ``opt`` leaves it to vibr, and
    a note of what was done with it."""
    pp_note = "refined in mapping" if opt.refine_principal_point else "fixed at the image centre"
    if turned_on_the_spot:
        pp_note = "fixed at the image centre (turned on the spot)"
    elif opt.refine_principal_point is None:
        t0 = time.perf_counter()
        rec, pp_note = _refine_principal_point(rec, opt.num_threads)
        times["principal_point"] = time.perf_counter() - t0
    logger.info(f"calibrate: principal point {pp_note}")
    return rec, pp_note


def _undistorted(rec, model_dir: Path, img_dir: Path, undist: Path, n_registered: int, opt: CalibrateOptions,
                 times: dict):
    """Step 5/5: the kept model written to ``model_dir`` and its images undistorted to
    PINHOLE in ``undist``; the undistorted reconstruction."""
    pycolmap = import_pycolmap()
    pycolmap.logging.minloglevel = 0 if opt.verbose else 2
    model_dir.mkdir(parents=True, exist_ok=True)
    rec.write(model_dir)  # the kept model (incremental_mapping also wrote it)
    t0 = time.perf_counter()
    logger.info(f"calibrate [5/5] undistorting {n_registered} images to PINHOLE")
    pycolmap.undistort_images(undist, model_dir, img_dir, output_type="COLMAP", num_threads=opt.num_threads)
    times["undistort"] = time.perf_counter() - t0
    return pycolmap.Reconstruction(undist / "sparse")


def _check_options(opt: CalibrateOptions, n_photos: int | None, photos_dir: Path) -> CalibrateOptions:
    """``opt`` checked (:class:`VibrInputError` naming ``photos_dir``); ``n_photos`` None for
    a video (its frames are counted as they are read)."""
    if not (0 < opt.scale <= 4):
        raise VibrInputError(f"scale must be in (0, 4], got {opt.scale}", photos_dir)
    if int(opt.frames) != opt.frames or opt.frames < 2:
        raise VibrInputError(f"frames must be an integer >= 2, got {opt.frames}", photos_dir)
    if opt.matcher is not None and opt.matcher not in MATCHERS:
        raise VibrInputError(f"matcher must be one of {', '.join(MATCHERS)}, got {opt.matcher!r}", photos_dir)
    if opt.camera_model not in CAMERA_MODELS:
        raise VibrInputError(
            f"camera model must be one of {', '.join(CAMERA_MODELS)}, got {opt.camera_model!r}", photos_dir
        )
    if int(opt.max_features) != opt.max_features or opt.max_features < 1:
        raise VibrInputError(f"max_features must be an integer >= 1, got {opt.max_features}", photos_dir)
    if int(opt.num_threads) != opt.num_threads or not (opt.num_threads >= 1 or opt.num_threads == -1):
        raise VibrInputError(f"num_threads must be an integer >= 1 (or -1: every core), got {opt.num_threads}",
                             photos_dir)
    if int(opt.min_registered) != opt.min_registered or opt.min_registered < 2:  # refused, not raised to 2
        raise VibrInputError(f"min_registered must be an integer >= 2 (a model needs two photos), "
                             f"got {opt.min_registered}", photos_dir)
    opt = replace(opt, min_registered=int(opt.min_registered))
    if n_photos is None and opt.frames < opt.min_registered:
        raise VibrInputError(f"frames ({opt.frames}) must be at least min_registered ({opt.min_registered})",
                             photos_dir)
    if n_photos is not None and n_photos < opt.min_registered:
        raise VibrInputError(
            f"{n_photos} photos found, calibrate needs at least {opt.min_registered}", photos_dir
        )
    return opt


def _check_frames(frames, opt: CalibrateOptions, video: Path) -> list[Path]:
    """The frames kept from a video, refused when fewer than ``min_registered``."""
    if len(frames.files) < opt.min_registered:
        raise VibrInputError(f"the video has {len(frames.files)} frames, calibrate needs at least "
                             f"{opt.min_registered}", video)
    return frames.files


def _clean_work(work: Path) -> tuple[Path, Path, Path, Path]:
    """The work folder's image folder, database, sparse and undistorted model paths, with
    whatever a previous run left there removed (a reused work folder starts clean)."""
    img_dir, db, sparse, undist = work / "images", work / "database.db", work / "sparse", work / "undistorted"
    for p in (db, Path(f"{db}-wal"), Path(f"{db}-shm"), sparse, undist, img_dir):
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()
    return img_dir, db, sparse, undist


def _extract_features(db: Path, img_dir: Path, names: list[str], sizes, opt: CalibrateOptions) -> float:
    """Step 2: SIFT features of every photo into the database (CPU). Returns seconds."""
    pycolmap = import_pycolmap()

    t0 = time.perf_counter()
    size = max(sizes, key=lambda wh: wh[0] * wh[1])
    logger.info(f"calibrate [2/5] SIFT features ({size[0]}x{size[1]}, {opt.camera_model}, "
                f"{'one shared camera' if opt.single_camera else 'one camera per photo'})")
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = opt.camera_model
    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = opt.num_threads
    ext.use_gpu = False
    ext.max_image_size = max(max(wh) for wh in sizes)
    ext.sift.max_num_features = int(opt.max_features)
    pycolmap.extract_features(
        db, img_dir, image_names=names,
        camera_mode=pycolmap.CameraMode.SINGLE if opt.single_camera else pycolmap.CameraMode.PER_IMAGE,
        reader_options=reader, extraction_options=ext, device=pycolmap.Device.cpu,
    )
    return time.perf_counter() - t0


def _match_features(db: Path, opt: CalibrateOptions) -> float:
    """Step 3: exhaustive or sequential matching with two-view geometric verification.
    Returns seconds."""
    pycolmap = import_pycolmap()

    t0 = time.perf_counter()
    logger.info(f"calibrate [3/5] {opt.matcher} matching")
    mopt = pycolmap.FeatureMatchingOptions()
    mopt.num_threads = opt.num_threads
    mopt.use_gpu = False
    vopt = pycolmap.TwoViewGeometryOptions()
    vopt.ransac.random_seed = opt.seed
    if opt.matcher == "exhaustive":
        pycolmap.match_exhaustive(db, matching_options=mopt, verification_options=vopt,
                                  device=pycolmap.Device.cpu)
    else:
        popt = pycolmap.SequentialPairingOptions()
        popt.num_threads = opt.num_threads
        pycolmap.match_sequential(db, matching_options=mopt, pairing_options=popt,
                                  verification_options=vopt, device=pycolmap.Device.cpu)
    return time.perf_counter() - t0


def _incremental_mapping(db: Path, img_dir: Path, sparse: Path, n_photos: int, opt: CalibrateOptions):
    """Step 4: COLMAP's incremental mapper (poses, intrinsics, sparse points), seeded,
    with a progress bar of the registered photos. Returns its reconstructions (dict)."""
    pycolmap = import_pycolmap()

    logger.info("calibrate [4/5] incremental mapping (poses, intrinsics, sparse points)")
    iopt = pycolmap.IncrementalPipelineOptions()
    iopt.num_threads = opt.num_threads
    iopt.random_seed = opt.seed
    iopt.mapper.random_seed = opt.seed
    iopt.triangulation.random_seed = opt.seed
    iopt.mapper.num_threads = opt.num_threads
    iopt.ba_refine_principal_point = bool(opt.refine_principal_point)
    sparse.mkdir()
    bar = progress(total=n_photos, desc="calibrate: registered")
    size = [0]  # photos in the model being built

    def _registered(new_model: bool) -> None:
        # COLMAP starts a new model where the last one stopped growing: the bar shows the
        # largest model so far (summing the models' registrations had shown 17/16)
        size[0] = 2 if new_model else size[0] + 1
        if size[0] > bar.n:
            bar.update(min(size[0], n_photos) - bar.n)

    try:
        return pycolmap.incremental_mapping(
            db, img_dir, sparse, options=iopt,
            initial_image_pair_callback=lambda: _registered(True),
            next_image_callback=lambda: _registered(False),
        )
    finally:
        bar.close()


def _kept_model(recs, names: list[str], stem: dict, photos_dir: Path, opt: CalibrateOptions):
    """The reconstruction with the most registered images: ``(key, reconstruction,
    registered names, unregistered names)``; too few registered photos raise
    :class:`VibrInputError` naming the others."""
    best_key, rec = None, None
    for k, r in (recs or {}).items():
        if rec is None or r.num_reg_images() > rec.num_reg_images():
            best_key, rec = k, r
    registered = sorted(im.name for im in rec.images.values() if _has_pose(im)) if rec else []
    unregistered = [n for n in names if n not in set(registered)]
    if len(registered) < opt.min_registered:
        raise VibrInputError(
            f"only {len(registered)} of {len(names)} photos registered (at least "
            f"{opt.min_registered} needed); not registered: "
            + ", ".join(stem[n] for n in unregistered),
            photos_dir,
        )
    if unregistered:  # a warning: the scene lacks them, which -q must not hide
        logger.warning(f"calibrate: {len(unregistered)} of {len(names)} photos not registered (left out): "
                       + ", ".join(stem[n] for n in unregistered))
    return best_key, rec, registered, unregistered


def _fit_one_centre(db: Path, opt: CalibrateOptions):
    """:func:`vibr.calib.pan.fit_one_centre` unless ``opt.pan`` is False; a fit that
    fails numerically leaves COLMAP's mapper to do the work, with a warning."""
    if opt.pan is False:
        return None
    try:
        return fit_one_centre(db, opt.seed, force=bool(opt.pan))
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
        logger.warning(f"calibrate: the fit of one centre for every photo failed ({exc}); COLMAP's mapper alone")
        return None


def _mapping_or_one_centre(one, db, img_dir, sparse, n_photos, opt, times) -> tuple[dict, Choice | None]:
    """COLMAP's mapper, or the model of one centre (:mod:`vibr.calib.pan`): asked for
    (``opt.pan``), or fitted because the pairs are related by homographies and then compared
    with the mapper's. Returns the models to keep the largest of, and the choice (None
    where there was none to make)."""
    if opt.pan and one.reconstruction is not None:
        logger.info("calibrate [4/5] one centre for every photo (as asked): rotations and intrinsics")
        recs, choice = {0: one.reconstruction}, Choice(True, "asked for (pan=True)")
    else:
        t0 = time.perf_counter()
        try:
            recs = _incremental_mapping(db, img_dir, sparse, n_photos, opt)
        finally:
            times["mapping"] = time.perf_counter() - t0
        if one is None:
            return recs, None
        choice = prefer_one_centre(one, max((recs or {}).values(), key=lambda r: r.num_reg_images(), default=None))
        if one.reconstruction is None:
            return recs, choice
        logger.info(f"calibrate: {one.homography_pairs} of {one.pairs} image pairs related by homographies; "
                    + ("one centre for every photo: " if choice.one_centre else "the mapper's centres: ")
                    + choice.why)
        recs = {0: one.reconstruction} if choice.one_centre else recs
    note = focal_note(one) if choice.one_centre else None
    if note:  # asked for or chosen, an implausible focal length is said
        logger.warning(f"calibrate: {note}; --pan no keeps COLMAP's mapper (docs/explanation/calibration.md)")
    return recs, choice


def _one_centre_summary(one, choice) -> dict:
    """calibration.json's record of the test (:mod:`vibr.calib.pan`); an error that
    could not be measured (no homography pairs, a model without points) is null."""
    def px(v):
        return round(float(v), 4) if np.isfinite(v) else None

    out = {"taken": bool(choice and choice.one_centre), "homography_pairs": f"{one.homography_pairs} of {one.pairs}",
           "pair_homographies_px": px(one.homography_px)}
    if one.fit is not None:
        out["matches_px"] = px(one.fit.median_px)
        out["focal_px"] = [round(float(p[0]), 2) for p in one.fit.params]
    if choice is not None:
        out["why"] = choice.why
        if choice.registered != (0, 0):
            out["registered"] = {"one_centre": choice.registered[0], "mapper": choice.registered[1]}
            out["points_px"] = {"one_centre": px(choice.points_px[0]), "mapper": px(choice.points_px[1])}
    return out


def _calibration_meta(photos_dir: Path, opt: CalibrateOptions, pp_note: str,
                      report: CalibrationReport, tool_version: str, frames=None) -> dict:
    """The scene's ``meta``: format "calibrate" and the calibration summary (with, from a
    video, the frames kept: their numbers, times and sharpness)."""
    meta = {
        "format": "calibrate",
        "calibration": {
            "tool": f"pycolmap {tool_version}",
            "photos": str(photos_dir),
            "scale": opt.scale,
            "matcher": opt.matcher,
            "camera_model": opt.camera_model,
            "single_camera": opt.single_camera,
            "principal_point": pp_note,
            "registered": report.registered,
            "unregistered": report.unregistered,
            "num_points": report.num_points,
            "mean_reprojection_error_px": report.mean_reprojection_error_px,
            "times_s": {k: round(v, 3) for k, v in report.times_s.items()},
        },
    }
    if frames is not None:
        info = frames.info
        meta["capture"] = "video"  # the views in time order (saved as vibr_capture)
        meta["calibration"]["video"] = {
            "size": [info.width, info.height], "fps": info.fps, "duration_s": info.duration_s,
            "frames_read": frames.n_read, "frames_kept": frames.indices,
            "times_s": [round(i / info.fps, 3) if info.fps > 0 else None for i in frames.indices],
            "sharpness_kept": [round(v, 2) for v in frames.sharpness],
            "sharpness_median_all": round(frames.median_sharpness, 2),
        }
    return meta


#: The "auto" principal-point refinement is kept only if the standard deviation of each
#: principal-point coordinate (from the bundle-adjustment covariance) is at most
#: ``PP_MAX_STD`` · max(W, H) and the shift at most ``PP_MAX_SHIFT`` · max(W, H).
PP_MAX_STD = 0.002
PP_MAX_SHIFT = 0.03


def _refine_principal_point(rec, num_threads: int):
    """Global bundle adjustment of a copy of ``rec`` with the principal point free, kept only
    if the data determine it.

    The covariance of the camera parameters at the optimum (``pycolmap.estimate_ba_covariance``,
    gauge fixed by three points) gives the standard deviation σ of each principal-point
    coordinate; the refinement is kept when every σ ≤ ``PP_MAX_STD`` · max(W, H) and the shift
    ≤ ``PP_MAX_SHIFT`` · max(W, H). On a level arc of views σ_y is large: the principal
    point trades off against a common pitch of the cameras (docs/explanation/calibration.md gives the
    values measured on fountain-P11 and on an arc).

    Returns ``(reconstruction, note)``: the refined copy or ``rec`` itself, and a note.
    """
    pycolmap = import_pycolmap()

    trial = pycolmap.Reconstruction(rec)
    opt = pycolmap.BundleAdjustmentOptions()
    opt.refine_principal_point = True
    opt.print_summary = False
    opt.ceres.solver_options.num_threads = num_threads
    cfg = pycolmap.BundleAdjustmentConfig()
    for iid in trial.reg_image_ids():
        cfg.add_image(iid)
    cfg.fix_gauge(pycolmap.BundleAdjustmentGauge.THREE_POINTS)
    try:
        ba = pycolmap.create_default_ceres_bundle_adjuster(opt, cfg, trial)
        ba.solve()
        cov = pycolmap.estimate_ba_covariance(pycolmap.BACovarianceOptions(), trial, ba)
    except Exception as exc:  # noqa: BLE001 - any solver failure means "keep the centre"
        return rec, f"kept at the image centre (refinement failed: {exc})"
    worst_std, shift = 0.0, 0.0
    for cid, cam in trial.cameras.items():
        size = max(cam.width, cam.height)
        C = cov.get_other_params_cov(cam.params) if cov is not None else None
        idx = list(cam.principal_point_idxs())
        if C is None or C.shape[0] != len(cam.params):
            return rec, "kept at the image centre (no covariance for the refinement)"
        std = np.sqrt(np.clip(np.diag(C)[idx], 0, None))
        worst_std = max(worst_std, float(std.max()) / size)
        c0 = rec.cameras[cid]
        d = np.hypot(cam.principal_point_x - c0.principal_point_x, cam.principal_point_y - c0.principal_point_y)
        shift = max(shift, d / size)
    if not (np.isfinite(worst_std) and worst_std <= PP_MAX_STD and shift <= PP_MAX_SHIFT):
        return rec, (f"kept at the image centre (refined: std {100 * worst_std:.2f}%, shift "
                     f"{100 * shift:.2f}% of the image size)")
    return trial, f"refined (std {100 * worst_std:.3f}%, shift {100 * shift:.2f}% of the image size)"


def calibrate(photos_dir, out_dir, *, overwrite: bool = False, **kwargs) -> Scene:
    """Calibrate a folder of photos and write a vibr scene (``transforms.json``, images,
    ``sparse_pc.ply``, and ``calibration.json``: registered / unregistered photos, point
    count, reprojection error, stage times) to ``out_dir``.

    Takes the keyword arguments of :func:`calibrate_scene`. The scene is written with
    :func:`vibr.io.save_scene` into a temporary sibling of ``out_dir`` renamed at the end:
    on any error nothing is left at ``out_dir``. An existing ``out_dir`` is an error unless
    ``overwrite``. Returns the scene (its ``meta["calibration"]`` holds the summary).
    """
    try:
        from ..io import save_scene
    except ImportError:
        raise VibrInputError("vibr.io.save_scene is not available in this installation", out_dir) from None

    out = Path(out_dir)
    if out.exists() and not overwrite:
        raise OutputExists("output folder already exists", out)
    if out.exists():
        check_not_input(out, [photos_dir])
        check_replaceable(out)  # overwrite replaces only a folder vibr wrote
    parent = out.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    scene, report = calibrate_scene(photos_dir, **kwargs)
    logger.info("calibrate: " + report.summary().replace("\n", "\ncalibrate: "))
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".part", dir=parent))
    try:
        save_scene(scene, tmp / "scene", overwrite=False)
        # The calibration summary beside transforms.json (registered images, errors, times).
        with open(tmp / "scene" / "calibration.json", "w") as fh:
            json.dump(scene.meta["calibration"], fh, indent=2)
        from ..io.outputs import replace_folder, write_marker

        write_marker(tmp / "scene")  # lists calibration.json too
        replace_folder(tmp / "scene", out, overwrite=overwrite)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    scene.root = out
    return scene


# ---------------------------------------------------------------------------- evaluation helpers
def similarity_align(src_pts, dst_pts) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity ``dst ≈ s · R · src + t`` (Umeyama 1991).

    Parameters
    ----------
    src_pts, dst_pts : (N, 3) arrays, N ≥ 3 non-collinear.

    Returns
    -------
    s : float, R : (3, 3) rotation, t : (3,).
    """
    X = np.asarray(src_pts, dtype=np.float64)
    Y = np.asarray(dst_pts, dtype=np.float64)
    mx, my = X.mean(0), Y.mean(0)
    Xc, Yc = X - mx, Y - my
    S = Yc.T @ Xc / len(X)
    U, d, Vt = np.linalg.svd(S)
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    var_x = (Xc**2).sum() / len(X)
    s = float(np.trace(np.diag(d) @ D) / var_x)
    t = my - s * R @ mx
    return s, R, t


def align_cameras(est: list[Camera], ref: list[Camera], align: str = "poses") -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``X_ref = s Rₛ X_est + t`` between two calibrations of the same views
    (see :func:`pose_errors` for the two ``align`` modes). Returns ``(s, Rₛ (3, 3), t (3,))``."""
    Ce = np.array([c.centre for c in est])
    Cr = np.array([c.centre for c in ref])
    if align == "centres":
        return similarity_align(Ce, Cr)
    if align != "poses":
        raise ValueError(f"align must be 'poses' or 'centres', got {align!r}")
    M = sum(cr.R.T @ ce.R for ce, cr in zip(est, ref))
    U, _, Vt = np.linalg.svd(M)
    Rs = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    Ec, Rc = Ce - Ce.mean(0), Cr - Cr.mean(0)
    s = float(np.sum((Ec @ Rs.T) * Rc) / np.sum(Ec**2))
    return s, Rs, Cr.mean(0) - s * Rs @ Ce.mean(0)


def pose_errors(est: list[Camera], ref: list[Camera], align: str = "poses") -> dict:
    """Per-view pose errors of ``est`` cameras after a similarity alignment to ``ref``.

    The similarity maps estimated world points to reference ones, ``X_ref = s Rₛ X_est + t``.

    * ``align="centres"``: Umeyama fit of the camera centres (:func:`similarity_align`).
      Ill-conditioned in rotation when the centres are nearly collinear (a short arc).
    * ``align="poses"`` (default): ``Rₛ`` is the chordal mean of ``R_ref,iᵀ R_est,i`` over
      the views (SVD projection of their sum onto SO(3)), then ``s, t`` are the least-squares
      fit of the centres with ``Rₛ`` fixed:
      ``s = Σ (Rₛ C̄_est,i)·C̄_ref,i / Σ ‖C̄_est,i‖²`` (C̄: centred), ``t = mean C_ref − s Rₛ mean C_est``.

    Rotation error of view i: the angle θ of ``M = R_ref,i (R_est,i Rₛᵀ)ᵀ`` in degrees
    (``‖M − I‖_F = 2√2 sin(θ/2)``); centre
    error: ``‖s Rₛ C_est,i + t − C_ref,i‖`` in reference units, and divided by the baseline
    span (largest distance between two reference centres).

    Returns a dict with ``rot_deg`` (N,), ``centre`` (N,), ``centre_rel`` (N,), ``span``,
    ``scale``.
    """
    Ce = np.array([c.centre for c in est])
    Cr = np.array([c.centre for c in ref])
    s, Rs, ts = align_cameras(est, ref, align)
    rot = []
    for ce, cr in zip(est, ref):
        M = cr.R @ (ce.R @ Rs.T).T
        # ‖M − I‖_F = 2√2 sin(θ/2): accurate for small angles, unlike arccos((tr M − 1)/2).
        rot.append(np.degrees(2 * np.arcsin(min(1.0, np.linalg.norm(M - np.eye(3)) / (2 * np.sqrt(2))))))
    cerr = np.linalg.norm((s * Ce @ Rs.T + ts) - Cr, axis=1)
    span = float(np.max(np.linalg.norm(Cr[:, None] - Cr[None], axis=2)))
    return {"rot_deg": np.array(rot), "centre": cerr, "centre_rel": cerr / span, "span": span, "scale": s}
