"""Photographs from a video (``vibr calibrate VIDEO``): the sharpest frame of each stretch.

A video walked round a scene holds thousands of frames, many blurred by the hand's motion,
and neighbours that differ by a few pixels. Structure from motion wants a few dozen sharp
photographs spread along the walk. The video is cut into ``n`` stretches of equal length,
and of each stretch the frame with the highest :func:`sharpness` within :data:`REACH_S` of
its middle is kept, weighted by up to :data:`CENTRE_PREFERENCE` towards the middle: the
spread comes from the stretches, the choice near the middle avoids the blur (which comes and
goes within a fraction of a second as the hand shakes and the walker steps) without
trading a blurred frame for a gap in the walk, and of frames about as sharp the middle one
keeps the kept frames evenly spaced (docs/explanation/calibration.md, "From a video"). The frames are read
once, as a stream: memory holds one stretch's best frame.
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import VibrInputError
from ..io.images import write_encoded
from ..io.video import VideoInfo, open_video
from ..progress import progress

logger = logging.getLogger(__name__)

__all__ = ["sharpness", "extract_frames", "VideoFrames", "DEFAULT_FRAMES"]

#: Frames kept from a video by default: enough views for depth and for a path, few enough
#: for COLMAP's matching on a laptop's CPU.
DEFAULT_FRAMES = 60

#: The longest side (pixels) :func:`sharpness` looks at: larger frames are sampled.
SHARPNESS_SIDE = 960

#: A frame at a stretch's end scores its sharpness times (1 − this), one in the middle its
#: sharpness: blur from the hand's motion divides the sharpness by much more than that, so a
#: blurred middle frame still loses to a sharp one off the middle.
CENTRE_PREFERENCE = 0.2

#: How far (seconds) from its stretch's middle a frame may be chosen: a long stretch's most
#: detailed frame is often just the one that looks at the most texture, and choosing it could
#: leave the views of a walk seconds apart on one side and a few frames apart on the other.
#: Half a second covers a step of the walker and many periods of the hand's tremor.
REACH_S = 0.5


def sharpness(img) -> float:
    """How sharp an image is: the variance of the Laplacian of its luminance,

    ``S = Var(∇²Y)``, with ``Y`` the mean of R, G, B, on every ``f``-th pixel of every
    ``f``-th row, ``f = ⌈max(H, W) / SHARPNESS_SIDE⌉``,

    after Pech-Pacheco et al., "Diatom autofocusing in brightfield microscopy: a comparative
    study", ICPR 2000. Blur removes the high frequencies the Laplacian keeps, so of two frames
    of one scene the blurred one scores lower. Taking every ``f``-th pixel, rather than a
    mean of ``f × f``, keeps what the frame has of them (folded to lower frequencies), and
    bounds the cost whatever the video's size. Only comparisons between
    frames of one video mean anything.

    Parameters
    ----------
    img : (H, W, 3) or (H, W) array, any dtype.
    """
    a = np.asarray(img)
    f = max(1, -(-max(a.shape[:2]) // SHARPNESS_SIDE))
    a = a[::f, ::f]
    if a.shape[0] < 3 or a.shape[1] < 3:
        return 0.0
    # channel by channel: a mean over the last axis strides through the interleaved RGB
    y = (a[..., 0].astype(np.float32) + a[..., 1] + a[..., 2]) / 3 if a.ndim == 3 else a.astype(np.float32)
    lap = y[:-2, 1:-1] + y[2:, 1:-1] + y[1:-1, :-2] + y[1:-1, 2:] - 4 * y[1:-1, 1:-1]  # inside the border
    return float(lap.var())


@dataclass
class VideoFrames:
    """What :func:`extract_frames` kept: the image ``files`` (named by frame number, in time
    order), the frame ``indices`` and their ``sharpness``, the video's ``info``, the number
    of frames read, and the median sharpness of those scored (the frames near the middles
    of the stretches, where the choice is made)."""

    files: list[Path]
    indices: list[int]
    info: VideoInfo
    n_read: int
    sharpness: list[float] = field(default_factory=list)
    median_sharpness: float = 0.0
    total: int = 0  # the frame count the stretches were cut for

    def summary(self) -> str:
        gain = np.median(self.sharpness) / self.median_sharpness if self.median_sharpness > 0 else float("nan")
        return (f"kept {len(self.files)} of {self.n_read} frames, the sharpest near the middle of each stretch "
                f"({gain:.2f}x the median sharpness of the frames it chose from)")


def _stretch(i: int, n_total: int, n: int) -> int:
    """The stretch of frame ``i`` among ``n`` equal stretches of ``n_total`` frames (frames past
    an underestimated total join the last one)."""
    return min(i * n // n_total, n - 1) if n_total > 0 else i


def _centre_weight(i: int, n_total: int, n: int, reach: float) -> float:
    """``1 − CENTRE_PREFERENCE · d`` for frame ``i``, ``d`` its distance from its stretch's
    middle over the half-width of the window it may be chosen in (half the stretch, or
    ``reach`` frames when that is shorter and at least 2); 0 outside that window."""
    if n_total <= n:
        return 1.0
    half = n_total / (2 * n)
    centre = (2 * _stretch(i, n_total, n) + 1) * half - 0.5
    window = reach if 2 <= reach < half else half
    d = abs(i - centre) / window
    return 0.0 if d > 1.0 else 1.0 - CENTRE_PREFERENCE * d


def _check_space(out: Path, n: int, info: VideoInfo) -> None:
    """Refuse to start when ``out``'s disk cannot hold ``n`` frames (BMP: 3 bytes a pixel)."""
    try:
        free = shutil.disk_usage(out).free
    except OSError:
        return
    need = 3.0 * info.width * info.height * n + 1024 * n
    if free < need:
        raise VibrInputError(f"{_mib(free)} free, {n} frames of {info.width}x{info.height} need about "
                             f"{_mib(need)}: free some space, or use --work DIR on another disk", out)


def _mib(b: float) -> str:
    return f"{b / 2**20:.1f} MiB" if b < 10 * 2**20 else f"{b / 2**20:.0f} MiB"


def _count_frames(path: Path) -> int:
    """Frames in the video, decoded (for containers that state no duration)."""
    import imageio_ffmpeg

    n, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    return int(n)


def extract_frames(video, out_dir, n: int = DEFAULT_FRAMES) -> VideoFrames:
    """Keep the sharpest frame of each of ``n`` equal stretches of ``video`` as image files
    ``frame_NNNNNN.bmp`` (NNNNNN the frame's number from 0) in ``out_dir`` (emptied first):
    BMP, lossless and far faster to write than PNG (docs/explanation/calibration.md), as calibration's
    first step reads them once and writes its own copies.

    The stretches are cut by the frame count the video's header gives (frame rate ×
    duration); a video that ends sooner (cut short, or a header that is wrong) is read a
    second time with the count its first reading found, with a warning. All frames are kept
    when the video has ``n`` or fewer. Raises :class:`VibrInputError` naming the video when
    it cannot be decoded or holds no frame.
    """
    video, out = Path(video), Path(out_dir)
    if int(n) != n or n < 1:
        raise VibrInputError(f"frames must be an integer >= 1, got {n}", video)
    kept = _read_stretches(video, out, int(n), None)
    if len(kept.files) < min(n, kept.n_read):  # stretches cut for frames that never came
        logger.warning(f"calibrate: {video.name} ended after {kept.n_read} of the {kept.total} frames its "
                       f"header announces (cut short?): reading it again for {min(n, kept.n_read)} frames")
        kept = _read_stretches(video, out, int(n), kept.n_read)
    if not kept.files:
        raise VibrInputError("the video holds no frame", video)
    logger.info(f"calibrate: {kept.summary()}")
    return kept


def _read_stretches(video: Path, out: Path, n: int, total: int | None) -> VideoFrames:
    """One reading of the video: the best frame of each stretch into ``out`` (emptied),
    the stretches cut for ``total`` frames (None: the header's count)."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    kept = VideoFrames([], [], None, 0)
    scores: list[float] = []
    with open_video(video) as (info, frames):
        kept.info = info
        total = total or info.n_frames or _count_frames(video)
        kept.total = total
        _check_space(out, min(n, max(total, 1)), info)
        logger.info(f"calibrate: video {video.name}: {info.width}x{info.height}"
                    f"{' (turned upright)' if info.rotated else ''}, {info.fps:.3g} fps, "
                    f"{info.duration_s:.1f} s, about {total} frames; keeping {min(n, max(total, 1))}")
        best = (-1.0, 0.0, -1, None)  # weighted and plain sharpness, index, frame of the current stretch
        current = 0
        reach = REACH_S * info.fps if info.fps > 0 else float("inf")
        for i, frame in enumerate(progress(frames, desc="calibrate: video frames", total=total or None)):
            k = _stretch(i, total, n)
            if k != current and best[3] is not None:
                _keep(best, out, kept)
                best = (-1.0, 0.0, -1, None)
            current = k
            kept.n_read = i + 1
            weight = _centre_weight(i, total, n, reach)
            if weight == 0.0:
                continue  # too far from the stretch's middle: not even scored
            s = sharpness(frame)
            scores.append(s)
            if s * weight > best[0]:
                best = (s * weight, s, i, frame.copy())
        if best[3] is not None:
            _keep(best, out, kept)
    kept.median_sharpness = float(np.median(scores)) if scores else 0.0
    return kept


def _keep(best, out: Path, kept: VideoFrames) -> None:
    _, s, i, frame = best
    f = out / f"frame_{i:06d}.bmp"
    write_encoded(f, frame, ".bmp")
    kept.files.append(f)
    kept.indices.append(i)
    kept.sharpness.append(s)
