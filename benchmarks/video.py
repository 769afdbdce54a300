"""Seconds per minute of 1080p footage for ``wbcgrade video``, against a plain ``lut3d`` pass.

    python benchmarks/video.py [--seconds 10] [--preset warm] [--per-shot]

Makes a 1080p, 25 fps test clip of ``--seconds`` seconds (a slow zoom over
``samples/seeding.jpg`` with ffmpeg's ``zoompan``, x264 + an AAC tone; kept in
benchmarks/out/video and reused), grades it with ``grade_video`` (default
settings: one grade per clip, x264 CRF 18 preset medium) and then runs the
floor: one plain ``ffmpeg -vf lut3d=<the same .cube>:interp=tetrahedral`` pass
with the same encoder settings and the audio copied (ffmpeg converts to
packed 8-bit rgb24 for it; ``wbcgrade video`` states the matrix and range and
converts to planar 8-bit gbrp). Prints a table of the
stages in seconds and in seconds per minute of footage (the two ffmpeg passes
scale with the footage's length, the fit is once per clip or shot), and the
ratio to the floor. Everything runs on the CPU (ffmpeg, x264).
"""

from __future__ import annotations

import argparse
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "video"


def make_clip(seconds: float) -> Path:
    from wbcgrade.video.ffmpeg import ffmpeg_exe

    path = OUT / f"zoom_1080p_{seconds:g}s.mp4"
    if path.exists():
        return path
    OUT.mkdir(parents=True, exist_ok=True)
    frames = round(seconds * 25)
    graph = (f"scale=3840:2160,zoompan=z='1+0.15*on/{frames}':x='iw/2-iw/zoom/2':"
             f"y='ih/2-ih/zoom/2':d={frames}:s=1920x1080:fps=25,trim=end_frame={frames},"
             "format=yuv420p,setparams=range=tv:colorspace=bt709:color_primaries=bt709:"
             "color_trc=bt709")
    subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", "-loop", "1",
                    "-framerate", "25", "-i", str(ROOT / "samples" / "seeding.jpg"),
                    "-f", "lavfi", "-i", f"sine=frequency=220:sample_rate=48000:duration={seconds}",
                    "-vf", graph, "-c:v", "libx264", "-crf", "18", "-preset", "fast",
                    "-c:a", "aac", "-shortest", str(path)], check=True)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--preset", default="warm")
    parser.add_argument("--per-shot", action="store_true")
    args = parser.parse_args()

    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import load_preset, resolve_preset
    from wbcgrade.video.ffmpeg import ffmpeg_exe, probe
    from wbcgrade.video.workflow import VideoSettings, grade_video

    clip = make_clip(args.seconds)
    info = probe(clip)
    styles = load_preset(resolve_preset(args.preset))
    graded, lut = OUT / "graded.mp4", OUT / "grade.cube"
    result = grade_video(clip, graded, styles, GradeOptions(),
                         settings=VideoSettings(per_shot=args.per_shot), lut=lut, overwrite=True)
    start = time.perf_counter()
    subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-nostdin", "-y",
                    "-i", str(clip), "-vf", f"lut3d=file={lut}:interp=tetrahedral",
                    "-c:v", "libx264", "-crf", "18", "-preset", "medium", "-c:a", "copy",
                    str(OUT / "floor.mp4")], check=True)
    floor = time.perf_counter() - start
    seconds = info.frames / info.fps
    scale = 60.0 / seconds  # the passes scale with the footage; the fit is once per clip
    t = result.timings
    rows = [("scan (decode small, sample)", t["scan"], t["scan"] * scale),
            ("grade (pool, fit, colour map)", t["grade"], t["grade"]),
            ("encode (lut3d + x264 pass)", t["encode"], t["encode"] * scale)]
    other = t["total"] - sum(r[1] for r in rows)  # probe, LUT files, --lut
    rows.append(("other (probe, files)", other, other))
    total_minute = sum(r[2] for r in rows)
    rows += [("total (wbcgrade video)", t["total"], total_minute),
             ("plain ffmpeg -vf lut3d (floor)", floor, floor * scale)]
    print(f"{info.width}x{info.height}, {info.fps:g} fps, {info.frames} frames "
          f"({seconds:.1f} s), {info.pix_fmt}; preset {args.preset}"
          + (", per shot" if args.per_shot else "") + f"; {len(result.shots)} shot(s)")
    print(f"| {'stage':<34} | {'s (this clip)':>13} | {'s per minute of footage':>23} |")
    print(f"|{'-' * 36}|{'-' * 15}|{'-' * 25}|")
    for name, clip_s, minute_s in rows:
        print(f"| {name:<34} | {clip_s:13.2f} | {minute_s:23.1f} |")
    print("(per minute: the passes scaled by 60 s / clip length, the fit counted once)")
    print(f"ratio to the floor: this clip {t['total'] / floor:.2f}, per minute "
          f"{total_minute / (floor * scale):.2f}; the encoding pass alone "
          f"{t['encode'] / floor:.2f}")

if __name__ == "__main__":
    main()
