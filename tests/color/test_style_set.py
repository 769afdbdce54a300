"""What a StyleSet tells other modules through typed members, not its ``meta`` dict."""

from __future__ import annotations

import numpy as np

from wbcgrade.color.io.cache import cache_folder, set_command_cache
from wbcgrade.color.presets import StyleSet, load_preset, resolve_preset


def test_a_subset_keeps_the_space_and_the_cache_and_a_preset_names_its_file(tmp_path):
    warm = load_preset(resolve_preset("warm"))
    part = warm.subset([2, 0])
    assert part.names == [warm.names[2], warm.names[0]]
    assert np.array_equal(part.histograms, warm.histograms[[2, 0]])
    assert part.working_space == warm.working_space and part.file_digest is None
    assert len(warm.file_digest) == 40  # the preset file's SHA-1
    own = StyleSet(["a"], np.ones((1, 2, 2, 2)) / 8, meta={"cache_dir": str(tmp_path)})
    off = StyleSet(["a"], np.ones((1, 2, 2, 2)) / 8, meta={"cache_dir": None})
    assert cache_folder(own) == tmp_path == own.subset([0]).cache_folder()
    assert cache_folder(off) is None  # the command turned caching off for this set
    set_command_cache(tmp_path / "command")
    try:
        assert cache_folder(StyleSet(["a"], own.histograms)) == tmp_path / "command"
        assert cache_folder(None) == tmp_path / "command"
    finally:
        set_command_cache()
