"""`wbcgrade video` without the ``video`` extra (imageio-ffmpeg): one line naming it."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_a_missing_ffmpeg_is_one_line_naming_the_extra(tmp_path):
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"\0" * 1000)
    script = ("import sys; sys.modules['imageio_ffmpeg'] = None  # not installed\n"
              "from wbcgrade.cli import main; main()")
    run = subprocess.run([sys.executable, "-c", script, "video", str(clip), "--preset", "warm",
                          "-o", str(tmp_path / "out.mp4")], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 1
    assert run.stderr.strip().splitlines() == [
        "Error: video needs ffmpeg: pip install 'wbcgrade[video]' "
        "(or: pip install imageio-ffmpeg)"], run.stderr
    assert not (tmp_path / "out.mp4").exists()
