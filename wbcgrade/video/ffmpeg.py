"""The ffmpeg binary of the ``imageio-ffmpeg`` wheel: probing, decoding, running a pass.

There is no ffprobe in that wheel, so :func:`probe` parses what ``ffmpeg -i``
prints (size, frame rate, pixel format, colour tags, streams) and counts the
frames with a stream copy (no decoding). Every conversion between the
footage's Y'CbCr and the RGB the grade works in is explicit
(:func:`to_rgb_filter`, :func:`from_rgb_filter`: ``scale`` with the input's
matrix and range), so the frames sampled for the fit and the frames the
LUT is applied to are the same RGB values, whatever ffmpeg's defaults.

:func:`run_pass` runs one ffmpeg command with a progress callback over
frames (``-progress pipe:1``); on any exception (Ctrl-C included) it kills
ffmpeg before re-raising. A failed run raises :class:`FfmpegError` with
ffmpeg's own reason (:func:`ffmpeg_reason`: the first specific error line, not
the "Terminating thread with return code -22" that follows it).

Inputs are opened with a demuxer allow-list (:func:`input_args`): playlists
and stream descriptions (ffconcat, HLS ``.m3u8``, DASH, IMF, SDP) and image
sequences, which make ffmpeg open other files (a FIFO among them would hang
it), are refused. Every ffmpeg run has a time limit; running past it is an
InputError, never a ``TimeoutExpired`` traceback.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from wbcgrade.errors import InputError, WbcgradeError

__all__ = ["FfmpegError", "VideoInfo", "ffmpeg_exe", "probe", "to_rgb_filter",
           "from_rgb_filter", "encoder_pixel_formats", "run_pass", "decode_frames",
           "file_arg", "input_args", "pixel_format", "ffmpeg_reason", "FIELD_ORDERS"]


#: The one line a run prints when the ``video`` extra is not installed.
MISSING_FFMPEG = ("video needs ffmpeg: pip install 'wbcgrade[video]' "
                  "(or: pip install imageio-ffmpeg)")


class FfmpegError(WbcgradeError):
    """ffmpeg failed (the message is its last error line)."""


@lru_cache(maxsize=1)
def ffmpeg_exe() -> str:
    """Path of the ffmpeg binary shipped in the ``imageio-ffmpeg`` wheel (the ``video`` extra:
    ``pip install 'wbcgrade[video]'``; WbcgradeError naming it when it is missing)."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise WbcgradeError(MISSING_FFMPEG) from None
    try:
        return imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as exc:  # pragma: no cover - a broken install
        raise WbcgradeError(f"no ffmpeg binary: {exc}") from None


def file_arg(path: str | os.PathLike) -> str:
    """A path as an ffmpeg file argument (absolute, ``file:`` so no protocol is guessed)."""
    return "file:" + str(Path(path).absolute())


#: Demuxers never used on an input: they open other files or streams named inside the
#: input (playlists, stream descriptions, image sequences, scripts).
REFUSED_DEMUXERS = frozenset({"concat", "hls", "dash", "imf", "webm_dash_manifest", "sdp",
                              "rtp", "rtsp", "image2", "avisynth", "vapoursynth",
                              "ffmetadata"})
_NOT_ON_WHITELIST = "Format not on whitelist"


def _run(args: list[str], timeout: float, path: str | os.PathLike | None = None,
         **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run`` of ffmpeg with a time limit that ends as an InputError."""
    try:
        return subprocess.run(args, capture_output=True, text=True, errors="replace",
                              timeout=timeout, **kwargs)
    except subprocess.TimeoutExpired:
        what = f"{path}: " if path is not None else ""
        raise InputError(f"{what}ffmpeg gave no answer within {timeout:g} s (an input that "
                         "never ends, such as a pipe or device?)") from None


@lru_cache(maxsize=1)
def _allowed_demuxers() -> str:
    run = _run([ffmpeg_exe(), "-hide_banner", "-demuxers"], timeout=60)
    names = []
    for line in run.stdout.splitlines():
        flags, rest = line[1:4], line[4:].split()
        if flags[:1] == "D" and "d" not in flags and rest and rest[0] not in REFUSED_DEMUXERS:
            names.append(rest[0])
    return ",".join(names)


def input_args(path: str | os.PathLike) -> list[str]:
    """``-i`` arguments for a clip: its demuxer must be on the allow-list (see module doc)."""
    allowed = _allowed_demuxers()
    return (["-format_whitelist", allowed] if allowed else []) + ["-i", file_arg(path)]


@lru_cache(maxsize=1)
def _pixel_formats() -> dict[str, tuple[int, int]]:
    run = _run([ffmpeg_exe(), "-hide_banner", "-pix_fmts"], timeout=60)
    table = {}
    for line in run.stdout.splitlines():
        match = re.match(r"[I.][O.][H.][P.][B.]\s+(\S+)\s+(\d+)\s+\d+\s+([\d-]+)", line)
        if match:
            depths = [int(b) for b in match.group(3).split("-") if b]
            table[match.group(1)] = (int(match.group(2)), max(depths, default=8))
    return table


def pixel_format(name: str) -> tuple[int, int, bool]:
    """(components, bits per component, has alpha) of an ffmpeg pixel format."""
    components, bits = _pixel_formats().get(name, (3, 8))
    return components, bits, components in (2, 4)


#: ffmpeg's words for a stream's field order -> the ``-field_order`` value.
FIELD_ORDERS = {"top first": "tt", "bottom first": "bb", "top coded first (swapped)": "tb",
                "bottom coded first (swapped)": "bt"}


#: swscale's names for the Y'CbCr matrices ffmpeg reports as colour spaces.
_MATRICES = {"bt709": "bt709", "bt470bg": "bt470", "smpte170m": "smpte170m",
             "bt2020nc": "bt2020", "bt2020c": "bt2020", "fcc": "fcc", "smpte240m": "smpte240m"}


@dataclass
class VideoInfo:
    """What ``ffmpeg -i`` says about a file's first video stream (and its other streams).

    Attributes
    ----------
    path : the file.
    width, height : frame size in pixels.
    fps : frame rate (frames per second; ``r_frame_rate``).
    pix_fmt : pixel format (``yuv420p``, ``yuv422p10le``, ``gbrp``...).
    color_range : "tv" (limited), "pc" (full) or None (untagged).
    colorspace, primaries, transfer : colour tags (None when untagged).
    frames : number of video frames (counted without decoding).
    duration : seconds (at least frames / fps).
    streams : kind of every stream in file order ("video", "audio", "subtitle", "data"...).
    codec : the video codec's name.
    field_order : "tt", "bb", "tb" or "bt" for interlaced footage (:data:`FIELD_ORDERS`),
        None for progressive or unknown.
    container_duration : seconds the container says it lasts (0: not said).
    """

    path: Path
    width: int
    height: int
    fps: float
    pix_fmt: str
    color_range: str | None
    colorspace: str | None
    primaries: str | None
    transfer: str | None
    frames: int
    duration: float
    streams: list[str] = field(default_factory=list)
    codec: str = ""
    field_order: str | None = None
    container_duration: float = 0.0

    @property
    def bits(self) -> int:
        """Bits per colour component."""
        return pixel_format(self.pix_fmt)[1]

    @property
    def alpha(self) -> bool:
        """Whether the frames carry an alpha channel."""
        return pixel_format(self.pix_fmt)[2]

    @property
    def interlaced(self) -> bool:
        return self.field_order is not None

    @property
    def is_rgb(self) -> bool:
        """Whether the frames are stored as RGB (no Y'CbCr matrix involved)."""
        return self.pix_fmt.startswith(("gbr", "rgb", "bgr", "argb", "abgr", "0rgb", "0bgr"))

    @property
    def high_depth(self) -> bool:
        """More than 8 bits per component."""
        return bool(re.search(r"(9|10|12|14|16)(le|be)?$|f(16|32)", self.pix_fmt))

    @property
    def matrix(self) -> str:
        """The Y'CbCr matrix used (swscale's name): the tag, else what players assume
        for untagged footage (BT.709 from 720 lines up, BT.601 below)."""
        if self.colorspace in _MATRICES:
            return _MATRICES[self.colorspace]
        return "bt709" if self.height >= 720 else "smpte170m"

    @property
    def range(self) -> str:
        """"pc" (full) or "tv" (limited; the default for untagged Y'CbCr)."""
        return "pc" if self.color_range == "pc" or self.is_rgb else "tv"

    def tags(self) -> dict[str, str]:
        """The colour tags the output gets: the input's, the assumed matrix's where untagged."""
        assumed = None if self.is_rgb else {"bt709": "bt709",
                                             "smpte170m": "smpte170m"}.get(self.matrix)
        space = self.colorspace or (None if self.is_rgb else assumed)
        tags = {"range": self.range,
                "colorspace": space or "",
                "color_primaries": self.primaries or (assumed or ""),
                "color_trc": self.transfer or ("bt709" if assumed else "")}
        return {k: v for k, v in tags.items() if v and v != "unknown"}

    @property
    def audio_streams(self) -> int:
        return self.streams.count("audio")


def _split_top(text: str) -> list[str]:
    """Split at commas outside parentheses."""
    parts, depth, current = [], 0, ""
    for char in text:
        if char == "(":
            depth += 1
        elif char == ")":
            depth -= 1
        if char == "," and depth == 0:
            parts.append(current.strip())
            current = ""
        else:
            current += char
    parts.append(current.strip())
    return parts


def _parse_video_line(line: str) -> dict:
    """The fields of ``Stream #0:0...: Video: h264 (High) (...), yuv420p(tv, bt709), 64x48 ...``."""
    body = line.split("Video:", 1)[1]
    parts = _split_top(body)
    out: dict = {"codec": parts[0].split()[0] if parts[0] else ""}
    for part in parts[1:]:
        fmt = re.fullmatch(r"([0-9a-z_]+)(?:\((.*)\))?", part)
        if fmt and "pix_fmt" not in out and not re.fullmatch(r"\d+x\d+.*", part):
            out["pix_fmt"] = fmt.group(1)
            for item in _split_top(fmt.group(2) or ""):
                item = item.strip()
                if item in ("tv", "pc"):
                    out["color_range"] = item
                elif item in FIELD_ORDERS:
                    out["field_order"] = FIELD_ORDERS[item]
                elif "/" in item or item in _MATRICES or item in ("gbr", "unknown", "ycgco"):
                    tags = item.split("/")
                    if len(tags) == 1:
                        tags = tags * 3
                    out["colorspace"], out["primaries"], out["transfer"] = (
                        None if t == "unknown" else t for t in tags[:3])
            continue
        size = re.match(r"(\d+)x(\d+)", part)
        if size and "width" not in out:
            out["width"], out["height"] = int(size.group(1)), int(size.group(2))
            continue
        rate = re.fullmatch(r"([\d.]+)(k?) (fps|tbr)", part)
        if rate:
            value = float(rate.group(1)) * (1000 if rate.group(2) else 1)
            out.setdefault(rate.group(3), value)
    return out


def _exact_rate(fps: float) -> float:
    """29.97 -> 30000/1001 (ffmpeg prints NTSC rates rounded)."""
    for base in (24, 30, 48, 60, 120):
        if abs(fps - base * 1000 / 1001) < 0.006:
            return base * 1000 / 1001
    return fps


def _refused_format(path: Path) -> InputError:
    return InputError(f"{path}: a playlist, stream description or image sequence (ffconcat, "
                      "HLS .m3u8, DASH, IMF, SDP...): these make ffmpeg open other files and "
                      "are not graded; grade the video files it names")


def probe(path: str | os.PathLike) -> VideoInfo:
    """Describe a video file -> VideoInfo; InputError when it is missing or not a video,
    a playlist (:func:`input_args`), or truncated or damaged (:func:`_count_frames`)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    run = _run([ffmpeg_exe(), "-hide_banner", "-nostdin", *input_args(path)], 120, path)
    text = run.stderr
    if _NOT_ON_WHITELIST in text:
        raise _refused_format(path)
    streams, video, container = [], None, 0.0
    for line in text.splitlines():
        duration = re.match(r"\s*Duration: (\d+):(\d+):([\d.]+)", line)
        if duration and not container:
            h, m, sec = duration.groups()
            container = int(h) * 3600 + int(m) * 60 + float(sec)
        match = re.match(r"\s*Stream #0:\d+.*?: (\w+):", line)
        if not match:
            continue
        kind = match.group(1).lower()
        streams.append(kind)
        if kind == "video" and video is None and "attached pic" not in line:
            video = _parse_video_line(line)
    if not streams:
        why = ffmpeg_reason(text, "unreadable")
        raise InputError(f"{path}: not a video ({why})")
    if video is None or "width" not in video or "pix_fmt" not in video:
        raise InputError(f"{path}: no video stream")
    fps = video.get("fps") or video.get("tbr")
    if not fps:
        raise InputError(f"{path}: the video stream has no frame rate (a still image?)")
    frames, duration = _count_frames(path, container)
    if frames < 1:
        raise InputError(f"{path}: the video stream has no frames")
    fps = _exact_rate(fps)
    return VideoInfo(path, video["width"], video["height"], fps, video["pix_fmt"],
                     video.get("color_range"), video.get("colorspace"), video.get("primaries"),
                     video.get("transfer"), frames, max(duration, frames / fps), streams,
                     video["codec"], video.get("field_order"), container)


#: What ffmpeg's demuxers and parsers print about a file that ends early or is damaged.
_DAMAGE = re.compile(r"partial file|corrupt input packet|truncat", re.I)


def _count_frames(path: Path, container: float = 0.0) -> tuple[int, float]:
    """(frames, seconds) of the first video stream, by a stream copy (no decoding).

    Not ``imageio_ffmpeg.count_frames_and_secs``: that one decodes every frame
    (``-vf null``: 2.3 s against 0.05 s for a 20 s 1080p clip here) and has
    no timeout. A file the demuxer finds damaged or ending early (an index
    that names frames past the end of a truncated file: "partial file") is an
    InputError: it would be graded into a shorter clip."""
    run = _run([ffmpeg_exe(), "-hide_banner", "-nostdin", *input_args(path),
                "-map", "0:v:0", "-c", "copy", "-f", "null", "-"], 600, path)
    frames = seconds = None
    for line in run.stderr.splitlines():
        match = re.search(r"frame=\s*(\d+)", line)
        if match:
            frames = int(match.group(1))
        match = re.search(r"time=\s*(-?)(\d+):(\d+):([\d.]+)", line)
        if match and not match.group(1):
            h, m, s = match.group(2, 3, 4)
            seconds = int(h) * 3600 + int(m) * 60 + float(s)
    if run.returncode != 0 or frames is None:
        raise InputError(f"{path}: cannot read the video stream ({ffmpeg_reason(run.stderr)})")
    damaged = [ln for ln in run.stderr.splitlines() if _DAMAGE.search(ln)]
    damage = next((ln for ln in damaged if "partial file" in ln), damaged[0] if damaged else None)
    if damage is not None:
        said = f" of the {container:.2f} s its header announces" if container else ""
        raise InputError(f"{path}: the file is truncated or damaged ({_strip_context(damage)}):"
                         f" only {frames} frames ({seconds or 0:.2f} s){said} can be read; "
                         "refusing to grade it into a shorter clip")
    return frames, seconds or 0.0


def _interlace(info: VideoInfo) -> str:
    """``scale`` option for interlaced footage: chroma converted field by field."""
    return ":interl=1" if info.interlaced else ""


def to_rgb_filter(info: VideoInfo, rgb_format: str, width: int | None = None,
                  height: int | None = None) -> str:
    """Filters turning the decoded frames into full-range RGB ``rgb_format`` (optionally
    resized, area-averaged), with the input's Y'CbCr matrix and range stated explicitly."""
    size = f"{width}:{height}:flags=area:" if width else ""
    if info.is_rgb:
        return f"scale={size.rstrip(':') or 'iw:ih'},format={rgb_format}"
    return (f"scale={size}in_color_matrix={info.matrix}:in_range={info.range}:out_range=pc"
            f"{'' if width else _interlace(info)},format={rgb_format}")


def from_rgb_filter(info: VideoInfo, pix_fmt: str) -> str:
    """Filters turning full-range RGB back into ``pix_fmt`` with the input's matrix and
    range, and tagging the frames with the input's colour tags and field order."""
    tags = ":".join(f"{k}={v}" for k, v in info.tags().items())
    is_rgb = pix_fmt.startswith(("gbr", "rgb", "bgr"))
    convert = (f"scale=out_color_matrix={info.matrix}:out_range={info.range}{_interlace(info)}"
               if not is_rgb else "scale")
    fields = ""
    if info.interlaced:
        fields = ",setfield=" + ("tff" if info.field_order in ("tt", "tb") else "bff")
    return f"{convert},format={pix_fmt}" + (f",setparams={tags}" if tags else "") + fields


@lru_cache(maxsize=16)
def encoder_pixel_formats(encoder: str) -> tuple[str, ...]:
    """Pixel formats an encoder accepts (its ``Supported pixel formats`` line)."""
    run = _run([ffmpeg_exe(), "-hide_banner", "-h", f"encoder={encoder}"], 60)
    for line in run.stdout.splitlines():
        if "Supported pixel formats:" in line:
            return tuple(line.split(":", 1)[1].split())
    if "is not recognized" in run.stdout + run.stderr:
        raise InputError(f"this ffmpeg has no {encoder} encoder")
    return ()


#: ffmpeg's lines that follow an error without saying what it was.
_GENERIC = re.compile(r"Terminating thread|Task finished with error|Error sending frames|"
                      r"Could not write header|Nothing was written|Conversion failed|"
                      r"Error opening output files?|Error opening input files?|"
                      r"Error while (filtering|processing)|Error initializing (filters|output)|"
                      r"^Error (opening|closing)", re.I)
_CONTEXT = re.compile(r"\[[^\]@]*@ 0x[0-9a-f]+\]\s*")


def _strip_context(line: str) -> str:
    """A log line without ffmpeg's ``[component @ 0x55...]`` prefixes."""
    return _CONTEXT.sub("", line).strip()


def ffmpeg_reason(stderr: str, default: str = "unknown error") -> str:
    """ffmpeg's own reason for a failure: the first error line that says what went wrong
    (e.g. "Could not find tag for codec subrip in stream #1, codec not currently
    supported in container"), not the generic lines after it."""
    lines = [_strip_context(ln) for ln in stderr.splitlines() if _strip_context(ln)]
    wanted = re.compile(r"error|invalid|no such|not |unable|cannot|could not|failed|"
                        r"divisible|unsupported|too (large|small|many)|denied|no space", re.I)
    specific = [ln for ln in lines if wanted.search(ln) and not _GENERIC.search(ln)]
    if specific:
        return specific[0]
    return lines[-1] if lines else default


def _die_with_parent() -> None:  # pragma: no cover - runs in the child
    """ffmpeg ends when this process dies (Linux), so a killed run writes nothing more."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def _start(args: list[str], cwd: str | None, stderr) -> subprocess.Popen:
    # Its own session: Ctrl-C reaches this process only, which then kills ffmpeg
    # (ffmpeg would otherwise finish and close a truncated file on its own).
    return subprocess.Popen([ffmpeg_exe(), "-hide_banner", "-nostdin", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=stderr, start_new_session=True,
                            preexec_fn=_die_with_parent if os.name == "posix" else None)


@contextlib.contextmanager
def _process(args: list[str], cwd: str | None = None) -> Iterator[tuple[subprocess.Popen, object]]:
    """Run ffmpeg; kill it on any exception; raise FfmpegError when it fails."""
    with tempfile.TemporaryFile() as errors:
        proc = _start(args, cwd, errors)
        try:
            yield proc, errors
        except BaseException:
            proc.kill()
            proc.wait()
            raise
        finally:
            if proc.stdout:
                proc.stdout.close()
        code = proc.wait()
        if code != 0:
            errors.seek(0)
            text = errors.read().decode("utf-8", "replace")
            raise FfmpegError(f"ffmpeg failed: {ffmpeg_reason(text)}")


def run_pass(args: list[str], progress: Callable[[int], None] | None = None,
             cwd: str | None = None) -> int:
    """Run ``ffmpeg ARGS``, calling ``progress(frames_done)`` as it goes -> frames done.

    ``-progress pipe:1 -nostats`` is added; ffmpeg is killed on any
    exception (KeyboardInterrupt included) before it propagates.
    """
    done = 0
    with _process(["-nostats", "-progress", "pipe:1", *args], cwd) as (proc, _):
        for raw in proc.stdout:
            line = raw.decode("ascii", "replace").strip()
            if line.startswith("frame="):
                with contextlib.suppress(ValueError):
                    done = int(line[6:])
                    if progress is not None:
                        progress(done)
    return done


def decode_frames(path: str | os.PathLike, info: VideoInfo, width: int | None = None,
                  height: int | None = None, alpha: bool = False) -> Iterator[np.ndarray]:
    """Every frame of the first video stream as (h, w, 3) uint8 RGB, in order
    (``alpha``: (h, w, 4) RGBA, the clip's alpha as the fourth channel).

    Converted with the input's matrix and range (:func:`to_rgb_filter`);
    optionally resized (area average) to ``width`` x ``height``. Frames are
    neither dropped nor duplicated (``-fps_mode passthrough``), so the k-th
    array is the frame the encoding pass's filters see as ``n = k``.
    """
    w, h = (width, height) if width else (info.width, info.height)
    channels, pix_fmt = (4, "rgba") if alpha else (3, "rgb24")
    size = w * h * channels
    args = [*input_args(path), "-map", "0:v:0", "-fps_mode", "passthrough",
            "-vf", to_rgb_filter(info, pix_fmt, width, height), "-f", "rawvideo",
            "-pix_fmt", pix_fmt, "-loglevel", "error", "pipe:1"]
    with _process(args) as (proc, _):
        while True:
            data = proc.stdout.read(size)
            if len(data) < size:
                break
            yield np.frombuffer(data, dtype=np.uint8).reshape(h, w, channels)
