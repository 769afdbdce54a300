"""A set's look from statistics content hardly moves (wbcgrade.color.look.statistics)."""

import numpy as np
import pytest

from wbcgrade.color.histogram import image_histogram
from wbcgrade.color.look.statistics import (
    LUMA,
    QUANTILES,
    palette_statistics,
    statistics_look,
    tinted_statistics,
)
from wbcgrade.color.mapping.remap import monochrome_map, monochrome_toning, to_monochrome


def natural_photo(seed, size=40):
    """A synthetic ungraded photo: a few colour regions from a shared everyday prior (skin,
    foliage, sky, greys, wood), its own exposure, a gradient and grain."""
    rng = np.random.default_rng(seed)
    prior = np.array([[0.85, 0.62, 0.5], [0.3, 0.45, 0.2], [0.45, 0.62, 0.85], [0.5, 0.5, 0.5],
                      [0.9, 0.9, 0.88], [0.15, 0.12, 0.1], [0.6, 0.45, 0.3], [0.7, 0.75, 0.8],
                      [0.8, 0.2, 0.15], [0.2, 0.3, 0.6]])
    colors = np.clip(prior[rng.choice(len(prior), 5, replace=False)] * rng.uniform(0.7, 1.15)
                     + rng.normal(0, 0.05, (5, 3)), 0, 1)
    labels = (np.arange(size)[:, None] * 5 // size + rng.integers(0, 5)) % 5
    image = colors[np.broadcast_to(labels, (size, size))]
    image = image * np.linspace(0.7, 1.1, size)[None, :, None]
    return np.clip(image + rng.normal(0, 0.02, image.shape), 0.0, 1.0)


def hists(images):
    return np.stack([image_histogram(i, 32) for i in images])


def faded_teal(rgb):
    """A film-like look: lifted blacks, softer whites, teal shadows, less saturation."""
    luma = (rgb @ LUMA)[..., None]
    out = luma + 0.5 * (rgb - luma)
    out = 0.12 + 0.8 * out
    shadow = np.clip(1.0 - 2.0 * luma, 0.0, 1.0)
    return np.clip(out + shadow * np.array([-0.06, 0.015, 0.05]), 0.0, 1.0)


def black_and_white(rgb):
    """A black-and-white film: luma through a contrast curve, no colour."""
    luma = rgb @ LUMA
    curve = np.clip(0.5 + 1.2 * (luma - 0.5), 0.0, 1.0)
    return np.repeat(curve[..., None], 3, axis=-1)


NATURALS = palette_statistics(hists([natural_photo(s) for s in range(100, 140)]))


def test_the_statistics_of_a_histogram_are_those_of_its_pixels():
    image = natural_photo(3, size=64)
    stats = palette_statistics(image_histogram(image, 32))
    luma = (image @ LUMA).ravel()
    assert np.allclose(stats.quantiles[0], np.quantile(luma, QUANTILES), atol=0.02)
    grey = np.repeat(np.random.default_rng(0).random((64, 64, 1)), 3, axis=2)
    assert palette_statistics(image_histogram(grey, 32)).spread[0] < 0.004  # binning removed
    assert stats.spread[0] > 0.05


def test_a_shared_look_is_found_and_ungraded_or_split_sets_stay_near_the_identity():
    contents = [natural_photo(s) for s in range(24)]
    test = np.concatenate([natural_photo(s) for s in range(200, 206)])
    before = np.mean(np.abs(faded_teal(test) - test))

    def estimate(images):  # the styles' content is of the naturals' kind: little bias
        return statistics_look(tinted_statistics(hists(images), NATURALS), NATURALS,
                               content_bias=0.25)

    found = estimate([faded_teal(c) for c in contents])
    assert np.mean(np.abs(found(test) - faded_teal(test))) < 0.5 * before
    assert found.saturation[2:7].max() < 0.95  # the set is less saturated...
    assert found.tone_out[1] > 0.04  # ...with lifted blacks
    # ungraded photos: no look (what content alone varies by is dropped)
    plain = estimate(contents)
    assert np.mean(np.abs(plain(test) - test)) < 0.25 * before
    # half the set warm, half cool: they cancel, nothing is applied with confidence
    warm = np.array([0.06, 0.0, -0.06])
    split = estimate([np.clip(c + (warm if i % 2 else -warm), 0, 1)
                      for i, c in enumerate(contents)])
    shift = split(test) - test
    assert np.abs(np.mean(shift @ np.array([1.0, 0.0, -1.0]))) < 0.03


def test_a_black_and_white_set_gives_black_and_white_and_its_tone_curve():
    contents = [natural_photo(s) for s in range(12)]
    found = statistics_look(tinted_statistics(hists([black_and_white(c) for c in contents]),
                                              NATURALS), NATURALS)
    assert found.monochrome
    test = np.concatenate([natural_photo(s) for s in range(200, 206)])
    out = found(test)
    assert np.abs(out - (out @ LUMA)[..., None]).max() < 1e-9  # no colour at all
    truth = black_and_white(test)
    assert np.mean(np.abs(out - truth)) < 0.5 * np.mean(np.abs(test - truth))


def test_a_sepia_set_keeps_its_toning():
    tone = np.array([0.05, 0.0, -0.08])

    def sepia(rgb):
        return np.clip(black_and_white(rgb) + tone * (1 - np.abs(2 * (rgb @ LUMA)[..., None]
                                                                  - 1)), 0, 1)

    contents = [natural_photo(s) for s in range(12)]
    found = statistics_look(tinted_statistics(hists([sepia(c) for c in contents]), NATURALS),
                            NATURALS)
    assert found.monochrome
    mid = found(np.array([[0.45, 0.5, 0.55]]))[0]
    chroma = mid - mid @ LUMA
    assert chroma[0] > 0.02 and chroma[2] < -0.03  # warm mid-tones, as every style has


def test_a_monochrome_map_is_recognised_and_projects_colours_onto_its_toning():
    axis = np.linspace(0, 1, 9)
    nodes = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1)
    colour_map = faded_teal(nodes)
    assert monochrome_toning(colour_map) is None
    mono = monochrome_map(colour_map)
    toning = monochrome_toning(mono)
    assert toning is not None
    pixels = np.random.default_rng(1).random((50, 3)).astype(np.float32)
    out = to_monochrome(pixels, toning)
    lumas = out @ LUMA
    expected = lumas[:, None] + np.stack([np.interp(lumas, toning[0], toning[1][:, c])
                                          for c in range(3)], 1)
    assert np.allclose(out, expected, atol=2e-3)


@pytest.mark.parametrize("n_naturals", [2, 5])
def test_few_natural_palettes_still_give_a_finite_look(n_naturals):
    naturals = palette_statistics(hists([natural_photo(s) for s in range(n_naturals)]))
    styles = palette_statistics(hists([faded_teal(natural_photo(s)) for s in range(20, 24)]))
    found = statistics_look(styles, naturals)
    out = found(np.random.default_rng(0).random((100, 3)))
    assert np.all(np.isfinite(out)) and out.min() >= 0 and out.max() <= 1


def test_the_grade_applies_the_look_a_style_set_supports_as_strongly_as_it_supports_it():
    from wbcgrade.color.look import set_extraction as look
    from wbcgrade.color.presets import StyleSet

    def style_set(images):
        return StyleSet([f"s{i}" for i in range(len(images))], hists(images),
                        meta={"cache_dir": None})

    naturals = style_set([natural_photo(s) for s in range(100, 140)])
    contents = [natural_photo(s) for s in range(12)]
    test = np.concatenate([natural_photo(s) for s in range(200, 204)])
    base, extracted, strength = look.set_look_base(style_set([faded_teal(c) for c in contents]),
                                                   naturals)
    # judged jointly against content: a look every style shows is sure and mostly applied
    assert extracted.info["method"] == "statistics" and extracted.info["rule"] == "posterior"
    assert extracted.info["probability"] > 0.99 and strength > 0.6
    before = np.mean(np.abs(faded_teal(test) - test))
    assert np.mean(np.abs(base(test) - faded_teal(test))) < 0.75 * before
    plain, plain_look, plain_strength = look.set_look_base(style_set(contents), naturals)
    assert np.mean(np.abs(plain(test) - test)) < 0.3 * before
    assert plain_strength < 0.5 * strength
    # --strength scales the look the set supports, and says so
    double, _, doubled = look.set_look_base(style_set([faded_teal(c) for c in contents]),
                                            naturals, 2.0)
    assert np.allclose(double.coefficients, 2.0 * base.coefficients)
    assert doubled == pytest.approx(2.0 * strength)
    mono, extracted, _ = look.set_look_base(
        style_set([black_and_white(c) for c in contents]), naturals)
    assert extracted.info["monochrome"]
    lattice = look.set_look_map(style_set([black_and_white(c) for c in contents]), naturals)[0]
    assert monochrome_toning(lattice) is not None  # exactly black and white as a LUT too


def test_the_users_own_photos_say_what_content_looks_like_in_their_collection(tmp_path):
    """A collection whose every photo is warm (its camera, its light): graded photos of it
    with no look are no warm look against the user's own photos, and are against others."""
    warm = np.array([0.06, 0.0, -0.06])

    def collection(seeds):
        return [np.clip(natural_photo(s) + warm, 0, 1) for s in seeds]

    styles = tinted_statistics(hists(collection(range(12))), NATURALS)
    against_others = statistics_look(styles, NATURALS, content_bias=0.0)
    own = palette_statistics(hists(collection(range(300, 320))))
    against_own = statistics_look(styles, NATURALS, reference=own)
    test = np.concatenate(collection(range(200, 204)))
    red_blue = np.array([1.0, 0.0, -1.0])  # the warmth each adds
    warmer_others = np.mean((against_others(test) - test) @ red_blue)
    assert warmer_others > 0.015
    assert abs(np.mean((against_own(test) - test) @ red_blue)) < 0.5 * warmer_others

    # a folder of them as --natural: beside the shipped palettes (three: too few to be used)
    import OpenImageIO as oiio

    from wbcgrade.color.look import load_naturals

    folder = tmp_path / "mine"
    folder.mkdir()
    for i, image in enumerate(collection(range(300, 303))):
        oiio.ImageBuf(np.ascontiguousarray(image, dtype=np.float32)).write(
            str(folder / f"p{i}.png"))
    naturals = load_naturals(str(folder), "sRGB Encoded Rec.709 (sRGB)")
    assert len(naturals.meta["own"].names) == 3 and len(naturals.names) > 3


def test_the_users_own_photos_count_as_far_as_their_number_says():
    """The centre leans from the natural medians towards the own photos' by their number
    (none below six: a median of a few photos moves as far as a faint look); a warm
    collection's own cast is taken for content more, the more of its photos are given."""
    from wbcgrade.color.look.statistics import MIN_OWN_PHOTOS, content_centre, own_photos_blend

    shares = [own_photos_blend(n) for n in (0, MIN_OWN_PHOTOS - 1, MIN_OWN_PHOTOS, 8, 50)]
    assert shares[:2] == [1.0, 1.0] and 1.0 > shares[2] > shares[3] > shares[4] > 0.0
    warm = np.array([0.06, 0.0, -0.06])

    def collection(seeds):
        return [np.clip(natural_photo(s) + warm, 0, 1) for s in seeds]

    styles = tinted_statistics(hists(collection(range(12))), NATURALS)
    test = np.concatenate(collection(range(200, 204)))
    alone = statistics_look(styles, NATURALS)
    few = statistics_look(styles, NATURALS,
                          reference=palette_statistics(hists(collection(range(300, 304)))))
    assert np.array_equal(few(test), alone(test)) and few.info["own_photos_unused"] == 4
    eight = palette_statistics(hists(collection(range(300, 308))))
    centre = content_centre(NATURALS, eight)
    natural_q, own_q = np.median(NATURALS.quantiles, 0), np.median(eight.quantiles, 0)
    share = own_photos_blend(8)
    assert np.allclose(centre.quantiles[0], share * natural_q + (1 - share) * own_q)
    # the styles' own photos, ungraded, as the user's: what is left is the natural share's
    own = palette_statistics(hists(collection(range(12))))
    moved = [np.sqrt(np.mean((look(test) - test) ** 2)) for look in (
        statistics_look(styles, NATURALS, content_bias=0.0),
        statistics_look(tinted_statistics(hists(collection(range(12))), NATURALS, own),
                        NATURALS, content_bias=0.0, reference=own))]
    assert moved[0] > 0.02 and moved[1] < 0.5 * moved[0]


def test_own_photos_missing_a_band_leave_it_to_the_natural_photos_and_evidence_is_stable():
    """A lightness band none of the own photos holds (dim photos: no highlights) keeps the
    natural median there, not NaN (which would drop the look's tint in that band); and a
    look's evidence does not depend on which centres were weighed before in the process."""
    from wbcgrade.color.look import statistics as stats

    dim = palette_statistics(hists([natural_photo(s) * 0.35 for s in range(300, 308)]))
    assert np.isnan(dim.band_neutral[:, -1]).all()
    centre = stats.content_centre(NATURALS, dim)
    top = np.nanmedian(NATURALS.band_neutral[:, -1], axis=0)
    assert np.allclose(centre.band_neutral[0, -1], top)
    styles = tinted_statistics(hists([faded_teal(natural_photo(s)) for s in range(12)]), NATURALS)
    stats._NULLS.clear()
    first = stats._look_evidence(styles, NATURALS, centre, 12)
    stats._NULLS.clear()
    stats._look_evidence(styles, NATURALS, NATURALS, 12)
    assert stats._look_evidence(styles, NATURALS, centre, 12) == first


def test_black_and_white_own_photos_say_nothing_of_how_colourful_content_is():
    """A colour look against own photos in black and white: they are not its content (taken
    for it, a warm look saturated colour photos 2-9 times); mixed, only the colour ones
    count."""
    from wbcgrade.color import look

    def warm(rgb):
        return np.clip(rgb * [1.08, 1.0, 0.9], 0, 1)

    images = [warm(natural_photo(s)) for s in range(12)]
    alone = statistics_look(tinted_statistics(hists(images), NATURALS), NATURALS)
    grey = palette_statistics(hists([black_and_white(natural_photo(s)) for s in range(300, 308)]))
    against = statistics_look(tinted_statistics(hists(images), NATURALS, grey), NATURALS,
                              reference=grey)
    assert np.allclose(against.saturation, alone.saturation)
    assert against.info["own_photos"] == 0 and against.info["own_photos_unused"] == 8
    mixed = [black_and_white(natural_photo(s)) for s in range(300, 306)]
    mixed += [natural_photo(s) for s in range(306, 314)]
    mixed = palette_statistics(hists(mixed))
    assert statistics_look(tinted_statistics(hists(images), NATURALS, mixed), NATURALS,
                           reference=mixed).info["own_photos"] == 8
    assert np.max(statistics_look(tinted_statistics(hists(images), NATURALS, mixed),
                                  NATURALS, reference=mixed).saturation) < 1.5
    from wbcgrade.color.presets import StyleSet

    folder = StyleSet([f"p{i}" for i in range(14)],
                      hists([black_and_white(natural_photo(s)) for s in range(300, 306)]
                            + [natural_photo(s) for s in range(306, 314)]),
                      meta={"cache_dir": None})
    assert len(look.colour_photos(folder).names) == 8
    # a folder of own photos (--natural DIR): its black-and-white ones are counted as unused
    styles = StyleSet([f"s{i}" for i in range(12)], hists(images), meta={"cache_dir": None})
    for own, used, unused in ((folder, 8, 6), (_subset(folder, range(6)), 0, 6)):
        with_own = look.set_extraction._beside_shipped(own, styles.working_space)
        info = look.set_look(styles, with_own, cache=False).info
        assert (info["own_photos"], info["own_photos_unused"]) == (used, unused)


def _subset(styles, indices):
    return styles.subset(list(indices))


def look_warm_muted(img):
    grey = img.mean(axis=-1, keepdims=True)
    return np.clip((grey + 0.5 * (img - grey)) * np.array([1.12, 1.0, 0.82]), 0.0, 1.0)


def test_the_halves_check_sees_the_own_photos_sampling_error_too():
    """Each half of a style set is measured against its half of the user's own photos, so
    the halves disagree by what those few photos happen to show, not only by the styles':
    two identical halves of styles agree exactly without own photos, not with them."""
    from wbcgrade.color import look
    from wbcgrade.color.histogram import grid_points
    from wbcgrade.color.presets import StyleSet

    def style_set(images, meta=None):
        return StyleSet([f"s{i}" for i in range(len(images))], hists(images),
                        meta={"cache_dir": None, **(meta or {})})

    # a clear look (warm, muted) every photo shows, so that neither half's look is nothing
    contents = [look_warm_muted(natural_photo(s)) for s in range(6)]
    styles = style_set([c for c in contents for _ in range(2)])  # halves: the same photos
    own = style_set([natural_photo(s) for s in range(300, 308)])
    plain = style_set([natural_photo(s) for s in range(100, 140)])
    naturals = style_set([natural_photo(s) for s in range(100, 140)], {"own": own})
    colors = grid_points(9)
    crossed = look.set_look_halves(styles, naturals)
    a, b = (half(colors) - colors for half in crossed)
    # the styles' halves are the same photos: only the own photos' halves differ
    assert np.sqrt(np.mean((a - b) ** 2)) > 0.002
    assert look.look_reliability(*crossed, colors) < 0.999
    a, b = (half(colors) - colors for half in look.set_look_halves(styles, plain))
    assert np.allclose(a, b)  # without own photos the two halves agree exactly


@pytest.mark.slow
def test_black_and_white_histograms_rebinned_from_a_finer_grid_hold_no_colour():
    """Style histograms come at the transfer grid (64^3, 128^3) and are re-binned to 32^3:
    the colour both binnings blur a grey into is taken off, so the set stays black and
    white (a 64^3 preset of black-and-white photos was taken for a colour one)."""
    from wbcgrade.color.presets import StyleSet

    grey = np.repeat(np.random.default_rng(2).random((80, 80, 1)), 3, axis=2)
    for bins in (64, 128):
        styles = StyleSet(["a"], image_histogram(grey, bins)[None])
        assert palette_statistics(styles.at_bins(32), source_bins=bins).spread[0] < 0.006
    assert palette_statistics(StyleSet(["a"], image_histogram(grey, 64)[None]).at_bins(32)
                              ).spread[0] > 0.01  # what it was without


def test_a_look_far_beyond_what_content_varies_by_is_shrunk_less():
    """The share of the natural spread taken for a collection's own difference eases for a
    set whose statistics stand far from the natural ones (a strong look), not for an
    ungraded set, whose look stays near the identity."""
    contents = [natural_photo(s) for s in range(24)]
    test = np.concatenate([natural_photo(s) for s in range(200, 206)])

    def strong(rgb):  # a cold, dark, desaturated look (a day for night)
        luma = (rgb @ LUMA)[..., None]
        return np.clip(0.55 * (luma + 0.3 * (rgb - luma)) + np.array([-0.03, 0.0, 0.06]), 0, 1)

    styles = hists([strong(c) for c in contents])
    eased = statistics_look(tinted_statistics(styles, NATURALS), NATURALS)
    held = statistics_look(tinted_statistics(styles, NATURALS), NATURALS, content_bias=1.0)
    assert eased.info["evidence"] > 2.0 and eased.info["content_bias"] < 0.7
    error = [np.mean(np.abs(look(test) - strong(test))) for look in (eased, held)]
    assert error[0] < 0.8 * error[1]
    plain = statistics_look(tinted_statistics(hists(contents), NATURALS), NATURALS)
    assert plain.info["evidence"] < 1.0 and plain.info["content_bias"] == 1.0
    assert np.mean(np.abs(plain(test) - test)) < 0.25 * np.mean(np.abs(strong(test) - test))


def test_a_look_that_moves_one_kind_of_statistic_far_counts_as_strong():
    """A mild bleach bypass moves saturation alone, too little for the mean over every
    statistic to stand out (0.8 of where ungraded sets stop, here): that kind's own
    evidence, against where random sets of as many natural photos stop, eases it."""
    contents = [natural_photo(s) for s in range(24)]

    def bleach(rgb):
        luma = (rgb @ LUMA)[..., None]
        return np.clip(luma + 0.75 * (rgb - luma), 0, 1)

    styles = hists([bleach(c) for c in contents])
    found = statistics_look(tinted_statistics(styles, NATURALS), NATURALS)
    held = statistics_look(tinted_statistics(styles, NATURALS), NATURALS, content_bias=1.0)
    assert found.info["evidence"] > 1.5 and found.info["content_bias"] < 0.6
    test = np.concatenate([natural_photo(s) for s in range(200, 206)])
    error = [np.mean(np.abs(look(test) - bleach(test))) for look in (found, held)]
    assert error[0] < 0.75 * error[1]
    assert error[0] < 0.75 * np.mean(np.abs(test - bleach(test)))


def test_a_tint_is_shrunk_as_a_whole_and_keeps_its_hue():
    """Each band's tint is shrunk by its size against what natural photos vary by, all its
    channels alike: a blue tint whose green part natural photos vary little in stays blue
    (shrunk channel by channel, it turned teal)."""
    from wbcgrade.color.look.statistics import _shrink_vectors

    tint = np.array([[-0.03, 0.004, 0.09]] * 3)
    sigma = np.array([[0.03, 0.004, 0.04]] * 3)
    kept = _shrink_vectors(tint, sigma)
    size = np.linalg.norm(tint, axis=1)
    cosine = np.sum(kept * tint, axis=1) / np.linalg.norm(kept, axis=1) / size
    assert np.all(cosine > 0.9999) and np.all(np.linalg.norm(kept, axis=1) > 0.4 * size)
    assert not _shrink_vectors(0.5 * sigma * np.array([1.0, -1.0, 0.0]), sigma).any()


def test_a_set_under_six_styles_keeps_the_full_share_and_is_not_weighed():
    """Medians of a few photos stand far from the natural ones without a look: such a set
    is neither eased nor trusted past its halves' check (no evidence is weighed)."""
    few = statistics_look(tinted_statistics(hists([faded_teal(natural_photo(s))
                                                   for s in range(4)]), NATURALS), NATURALS)
    assert few.info["evidence"] is None and few.info["content_bias"] == 1.0


def test_natural_palettes_left_out_by_name_are_told_apart_from_other_exclusions():
    """Two benchmarks holding out different photos get different natural statistics: a
    subset of the shipped file is keyed by the names it keeps too (two exclusions of one
    size shared a key, so the second was served the first's cached statistics)."""
    from wbcgrade.color.look.set_extraction import (
        _palettes_digest,
        natural_palettes,
        natural_statistics,
    )

    whole = natural_palettes()
    first = natural_palettes(exclude={whole.names[0]})
    second = natural_palettes(exclude={whole.names[1]})
    assert len(first.names) == len(second.names) == len(whole.names) - 1
    assert _palettes_digest(first) != _palettes_digest(second)
    assert _palettes_digest(whole) != _palettes_digest(first)
    kept_first = natural_statistics(first).quantiles
    kept_second = natural_statistics(second).quantiles
    assert not np.array_equal(kept_first, kept_second)
    np.testing.assert_array_equal(kept_first[0], natural_statistics(whole).quantiles[1])
