"""Videos through imageio-ffmpeg (which ships its own ffmpeg binary): H.264 in MP4 (the
default; also .mov and .mkv), VP9 in WebM, and GIF (:data:`VIDEO_FORMATS`, by extension).

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
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .._runtime.atomic import atomic_path
from ..errors import OutputFailed, VibrInputError

logger = logging.getLogger(__name__)

__all__ = ["write_video", "read_video_info", "even_pad", "BT709_FILTER", "BT709_TAGS", "VIDEO_FORMATS",
           "is_video", "VideoFormat", "VIDEO_INPUTS", "is_video_input", "VideoInfo", "open_video"]

#: RGB → YUV with the BT.709 matrix, and the stream tagged BT.709 (matrix, primaries,
#: transfer, limited range): players read untagged HD video as BT.709 whatever matrix made
#: it, and ffmpeg's default matrix is BT.601 (what that cost: docs/explanation/flythrough.md, "Video").
BT709_FILTER = ("scale=out_color_matrix=bt709:out_range=tv,"
                "setparams=color_primaries=bt709:color_trc=bt709:colorspace=bt709:range=tv")
BT709_TAGS = ("-colorspace", "bt709", "-color_primaries", "bt709", "-color_trc", "bt709", "-color_range", "tv")


@dataclass(frozen=True)
class VideoFormat:
    """How one video file extension is encoded: ``codec`` (ffmpeg's output arguments for a
    ``crf`` and x264 ``preset``), ``even`` (yuv420p: sizes padded to even), ``what`` (help)."""

    what: str
    codec: Callable[[int, str], list]
    even: bool = True


def _h264(container: str, *extra: str):
    return lambda crf, preset: ["-vf", BT709_FILTER, "-vcodec", "libx264", "-pix_fmt", "yuv420p", *BT709_TAGS,
                                "-crf", str(int(crf)), "-preset", preset, *extra, "-f", container]


def _vp9(crf, preset):  # constant quality (-b:v 0); cpu-used 4: x264 medium's speed, about
    return ["-vf", BT709_FILTER, "-vcodec", "libvpx-vp9", "-pix_fmt", "yuv420p", *BT709_TAGS, "-crf", str(int(crf)),
            "-b:v", "0", "-deadline", "good", "-cpu-used", "4", "-row-mt", "1", "-f", "webm"]


def _gif(crf, preset):  # one palette of 256 colours for the whole video, dithered
    return ["-vf", "split[a][b];[a]palettegen=stats_mode=full[p];[b][p]paletteuse=dither=sierra2_4a",
            "-loop", "0", "-f", "gif"]


#: Output formats by extension. GIF stores each frame's duration in hundredths of a second,
#: so its frame rate is 100 / round(100 / fps) (24 fps plays at 25).
VIDEO_FORMATS = {
    ".mp4": VideoFormat("H.264 in MP4, what every player plays", _h264("mp4", "-movflags", "+faststart")),
    ".mov": VideoFormat("H.264 in QuickTime", _h264("mov", "-movflags", "+faststart")),
    ".mkv": VideoFormat("H.264 in Matroska", _h264("matroska")),
    ".webm": VideoFormat("VP9 in WebM, for web pages", _vp9),
    ".gif": VideoFormat("GIF, one 256-colour palette, for READMEs and chat", _gif, even=False),
}


def is_video(path) -> bool:
    """Whether ``path``'s extension is one of :data:`VIDEO_FORMATS`."""
    return os.path.splitext(os.fspath(path))[1].lower() in VIDEO_FORMATS


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
    """Encode frames (an iterable of (H, W, 3) uint8, or float in [0, 1]) as a video of the
    format of ``path``'s extension (:data:`VIDEO_FORMATS`).

    Returns ``(n_frames, width, height)`` of the encoded video (sizes after padding).
    Raises :class:`VibrInputError` for no frames, frames of different sizes, a bad
    ``crf`` or ``fps``, and :class:`vibr.errors.OutputFailed` when ffmpeg fails (a full
    disk: ffmpeg's exit status is checked, and its messages are kept for the error line
    rather than printed).
    """
    p = os.fspath(path)
    check_video_options(p, fps=fps, crf=crf)
    fmt = VIDEO_FORMATS.get(os.path.splitext(p)[1].lower())
    if fmt is None:
        raise VibrInputError(f"not a video extension (one of {', '.join(VIDEO_FORMATS)})", p)
    n = 0
    size = None
    with atomic_path(p) as tmp, tempfile.TemporaryFile() as log:
        proc = None
        try:
            for img in frames:
                f = even_pad(_as_uint8(img)) if fmt.even else _as_uint8(img)
                if size is None:
                    size = (f.shape[1], f.shape[0])
                    proc = _start_ffmpeg(tmp, size, fps, fmt.codec(crf, preset), log)
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


def _start_ffmpeg(out, size, fps, codec: list, log):
    """ffmpeg reading raw RGB frames of ``size`` on its stdin, writing ``codec`` (output
    arguments, :data:`VIDEO_FORMATS`) to ``out`` (its own session: a Ctrl-C reaches vibr,
    which stops it and removes the file)."""
    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-f", "rawvideo", "-vcodec", "rawvideo",
           "-s", f"{size[0]}x{size[1]}", "-pix_fmt", "rgb24", "-r", f"{float(fps):.10g}", "-i", "-",
           "-an", "-v", "error", *codec, out]
    return subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log,
                            start_new_session=True)


def _finish_ffmpeg(proc, log, path) -> None:
    """Close ffmpeg's input, wait, and raise :class:`OutputFailed` with its last message
    when it did not end well."""

    with contextlib.suppress(BrokenPipeError):
        proc.stdin.close()
    if proc.wait() == 0:
        return
    log.seek(0)
    lines = [ln.strip() for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    rc = proc.returncode
    if lines:
        why = _without_tag(lines[-1])
    else:
        why = f"stopped by {signal.Signals(-rc).name}" if -rc in signal.valid_signals() else f"exit status {rc}"
    raise OutputFailed(f"cannot write the video: ffmpeg: {why}", path)


#: Video files read as input (``vibr calibrate``), by extension: what phones and cameras
#: write, decoded by imageio-ffmpeg's ffmpeg.
VIDEO_INPUTS = (".mp4", ".mov", ".m4v", ".mkv", ".webm", ".avi", ".mts", ".m2ts")


def is_video_input(path) -> bool:
    """Whether ``path`` is a file with one of the :data:`VIDEO_INPUTS` extensions."""
    return os.path.splitext(os.fspath(path))[1].lower() in VIDEO_INPUTS and os.path.isfile(path)


@dataclass(frozen=True)
class VideoInfo:
    """A video's frame size as decoded (after the display rotation a phone stores, which
    ffmpeg applies), frame rate, duration (0 when the container does not say) and
    ``n_frames``, the frame count those two give (an estimate: the decoder has the last
    word)."""

    width: int
    height: int
    fps: float
    duration_s: float
    rotated: bool

    @property
    def n_frames(self) -> int:
        return max(int(round(self.fps * self.duration_s)), 0)


@contextlib.contextmanager
def open_video(path):
    """``with open_video(path) as (info, frames)``: the :class:`VideoInfo` and an iterator
    of (H, W, 3) uint8 RGB frames, upright (ffmpeg applies the display rotation); ffmpeg is
    stopped on leaving. An unreadable file raises :class:`VibrInputError` naming it, with
    ffmpeg's last message."""
    import imageio_ffmpeg

    p = os.fspath(path)
    reader = imageio_ffmpeg.read_frames(p)
    quiet = logging.getLogger("imageio_ffmpeg")
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # its warning on a rotated video's size: expected, and said in our log
    try:
        meta = reader.__next__()
    except (OSError, RuntimeError, StopIteration) as exc:
        reader.close()
        raise VibrInputError(f"cannot read the video: {_ffmpeg_reason(str(exc))}", p) from None
    finally:
        quiet.setLevel(level)
    w, h = (int(v) for v in meta["size"])
    info = VideoInfo(w, h, float(meta.get("fps") or 0.0), float(meta.get("duration") or 0.0),
                     tuple(meta.get("source_size", (w, h))) != (w, h))

    def frames():
        for b in reader:
            yield np.frombuffer(b, np.uint8).reshape(h, w, 3)

    try:
        yield info, frames()
    finally:
        reader.close()


def _without_tag(line: str) -> str:
    """An ffmpeg message without the ``[component @ 0x…]`` it starts with."""
    return re.sub(r"^\[[^\]]*\]\s*", "", line)


#: What ffmpeg's messages mean for a user, first match wins: (what ffmpeg says, what to say).
_FFMPEG_REASONS = (
    ("does not contain any stream", "it holds no video stream (a sound file?)"),
    ("partial file", "the file is cut short (an interrupted copy or download?)"),
    ("Invalid data found", "ffmpeg cannot decode it (a damaged file, or not a video)"),
)


def _ffmpeg_reason(text: str) -> str:
    """What ffmpeg's messages say went wrong: a known cause (:data:`_FFMPEG_REASONS`), else
    the last line that says something (its banner and configuration are not the reason)."""
    for said, meaning in _FFMPEG_REASONS:
        if said in text:
            return meaning
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.startswith(" ")]
    skip = ("ffmpeg version", "built with", "configuration:", "lib", "===", "Could not load meta")
    useful = [ln for ln in lines if not ln.startswith(skip)]
    return _without_tag(useful[-1]) if useful else "ffmpeg could not decode it"


def read_video_info(path) -> tuple[int, int, int, float]:
    """Decode a video and return ``(n_frames, width, height, fps)`` (counts decoded frames)."""
    with open_video(path) as (info, frames):
        n = sum(1 for _ in frames)
    return n, info.width, info.height, info.fps
