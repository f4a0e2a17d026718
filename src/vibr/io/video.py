"""H.264 MP4 video through imageio-ffmpeg (which ships its own ffmpeg binary).

``yuv420p`` (what every player decodes) stores chroma at half resolution and so needs even
frame sizes: an odd width or height is **padded** by one row / column repeating the last
one (never cropped; the decoded video is then one pixel larger, which
:func:`write_video` reports). Quality: x264's constant rate factor ``crf`` (0 lossless,
18 visually lossless — the default —, 23 x264's own default, 51 worst). Colours are
converted and tagged as BT.709 (:data:`BT709_FILTER`), what players assume.
The file is written under a temporary name and renamed when complete.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import signal
import subprocess
import tempfile

import numpy as np

from ..errors import VibrInputError
from .atomic import atomic_path

logger = logging.getLogger(__name__)

__all__ = ["write_video", "read_video_info", "even_pad", "BT709_FILTER", "BT709_TAGS"]

#: RGB → YUV with the BT.709 matrix, and the stream tagged BT.709 (matrix, primaries,
#: transfer, limited range): players read untagged HD video as BT.709 whatever matrix made
#: it, and ffmpeg's default matrix is BT.601 (what that cost: docs/FLYTHROUGH.md, "Video").
BT709_FILTER = ("scale=out_color_matrix=bt709:out_range=tv,"
                "setparams=color_primaries=bt709:color_trc=bt709:colorspace=bt709:range=tv")
BT709_TAGS = ("-colorspace", "bt709", "-color_primaries", "bt709", "-color_trc", "bt709", "-color_range", "tv")


def even_pad(frame: np.ndarray) -> np.ndarray:
    """Pad an (H, W, 3) uint8 frame to even H and W by repeating its last row / column."""
    h, w = frame.shape[:2]
    ph, pw = h % 2, w % 2
    if not (ph or pw):
        return frame
    return np.pad(frame, ((0, ph), (0, pw), (0, 0)), mode="edge")


def _as_uint8(img) -> np.ndarray:
    a = np.asarray(img)
    if a.dtype != np.uint8:
        a = np.clip(np.rint(np.asarray(a, np.float32) * 255.0), 0, 255).astype(np.uint8)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    return np.ascontiguousarray(a[..., :3])


#: the highest frame rate accepted (a typo such as 24000 would give an unplayable file)
MAX_FPS = 1000.0


def check_video_options(path, *, fps: float, crf: int = 18) -> None:
    """One-line :class:`VibrInputError` naming ``path`` for a ``crf`` outside 0..51 or an
    ``fps`` that is not in (0, :data:`MAX_FPS`]: checked before frames are rendered."""
    if not (0 <= int(crf) <= 51):
        raise VibrInputError(f"crf must be in 0..51, got {crf}", os.fspath(path))
    if not (np.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise VibrInputError(f"fps must be in (0, {MAX_FPS:g}], got {fps}", os.fspath(path))


def write_video(path, frames, *, fps: float, crf: int = 18, preset: str = "medium") -> tuple[int, int, int]:
    """Encode frames (an iterable of (H, W, 3) uint8, or float in [0, 1]) as H.264 MP4.

    Returns ``(n_frames, width, height)`` of the encoded video (sizes after padding).
    Raises :class:`VibrInputError` for no frames, frames of different sizes, a bad
    ``crf`` or ``fps``, and :class:`vibr.errors.OutputFailed` when ffmpeg fails (a full
    disk: ffmpeg's exit status is checked, and its messages are kept for the error line
    rather than printed).
    """
    p = os.fspath(path)
    check_video_options(p, fps=fps, crf=crf)
    n = 0
    size = None
    with atomic_path(p) as tmp, tempfile.TemporaryFile() as log:
        proc = None
        try:
            for img in frames:
                f = even_pad(_as_uint8(img))
                if size is None:
                    size = (f.shape[1], f.shape[0])
                    proc = _start_ffmpeg(tmp, size, fps, crf, preset, log)
                elif (f.shape[1], f.shape[0]) != size:
                    raise VibrInputError(f"frame {n} is {f.shape[1]}x{f.shape[0]}, the video {size[0]}x{size[1]}", p)
                try:
                    proc.stdin.write(f.tobytes())
                except BrokenPipeError:  # ffmpeg stopped: its status and message say why
                    break
                n += 1
            if proc is None:
                raise VibrInputError("no frames to write", p)
            _finish_ffmpeg(proc, log, p)
        finally:
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    return n, size[0], size[1]


def _start_ffmpeg(out, size, fps, crf, preset, log):
    """ffmpeg reading raw RGB frames of ``size`` on its stdin, writing H.264 to ``out``
    (its own session: a Ctrl-C reaches vibr, which stops it and removes the file)."""
    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-f", "rawvideo", "-vcodec", "rawvideo",
           "-s", f"{size[0]}x{size[1]}", "-pix_fmt", "rgb24", "-r", f"{float(fps):.10g}", "-i", "-",
           "-an", "-vf", BT709_FILTER, "-vcodec", "libx264", "-pix_fmt", "yuv420p", *BT709_TAGS,
           "-crf", str(int(crf)), "-preset", preset, "-movflags", "+faststart", "-v", "error", "-f", "mp4", out]
    return subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log,
                            start_new_session=True)


def _finish_ffmpeg(proc, log, path) -> None:
    """Close ffmpeg's input, wait, and raise :class:`OutputFailed` with its last message
    when it did not end well."""
    from ..errors import OutputFailed

    with contextlib.suppress(BrokenPipeError):
        proc.stdin.close()
    if proc.wait() == 0:
        return
    log.seek(0)
    lines = [ln.strip() for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    rc = proc.returncode
    if lines:
        why = re.sub(r"^\[[^\]]*\]\s*", "", lines[-1])
    else:
        why = f"stopped by {signal.Signals(-rc).name}" if -rc in signal.valid_signals() else f"exit status {rc}"
    raise OutputFailed(f"cannot write the video: ffmpeg: {why}", path)


def read_video_info(path) -> tuple[int, int, int, float]:
    """Decode a video and return ``(n_frames, width, height, fps)`` (counts decoded frames)."""
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(os.fspath(path))
    meta = reader.__next__()
    n = sum(1 for _ in reader)
    w, h = meta["size"]
    return n, int(w), int(h), float(meta.get("fps", 0.0))
