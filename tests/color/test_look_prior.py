"""The prior over looks and the joint posterior of a set's statistics
(wbcgrade.color.look.edits, wbcgrade.color.look.prior)."""

import numpy as np
import pytest

from wbcgrade.color.histogram import grid_points, image_histogram
from wbcgrade.color.look.edits import Edit, random_edit
from wbcgrade.color.look.prior import (
    build_prior,
    content_noise,
    load_prior,
    posterior_look,
    push_edit,
)
from wbcgrade.color.look.statistics import LookDifferences, look_differences, palette_statistics


def test_the_empty_edit_changes_nothing_and_random_edits_stay_in_the_cube():
    points = grid_points(9)
    assert np.allclose(Edit()(points), points)
    rng = np.random.default_rng(1)
    moved = [random_edit(rng) for _ in range(50)]
    assert all(np.all((e(points) >= 0) & (e(points) <= 1)) for e in moved)
    sizes = [np.mean(np.abs(e(points) - points)) for e in moved]
    assert min(sizes) < 0.01 and max(sizes) > 0.05  # from traces to heavy looks


def test_an_edit_pushes_a_histogram_as_it_moves_its_pixels():
    rng = np.random.default_rng(2)
    image = rng.random((24, 24, 3))
    edit = Edit(saturation=0.5, contrast=0.4, black=0.05)
    pushed = push_edit(image_histogram(image, 16), edit)
    direct = image_histogram(edit(image), 16)
    colours = grid_points(16)
    means = [h.reshape(-1) @ colours for h in (pushed, direct)]
    assert np.allclose(*means, atol=0.01)


def _palettes(seeds, edit=None):
    out = []
    for s in seeds:
        rng = np.random.default_rng(s)
        image = np.clip(rng.random((1, 3)) * 0.8 + rng.normal(0, 0.15, (30, 30, 3)), 0, 1)
        out.append(image_histogram(image if edit is None else edit(image), 16))
    return np.stack(out)


def test_the_prior_is_a_second_moment_of_what_edits_do_to_the_statistics():
    naturals = _palettes(range(20))
    moment = build_prior(naturals, edits=12, sample=8)
    assert moment.shape == (42, 42) and np.allclose(moment, moment.T)
    assert np.min(np.linalg.eigvalsh(moment)) > -1e-12 and np.trace(moment) > 0
    shipped = load_prior()
    assert shipped.shape == (42, 42) and np.all(np.isfinite(shipped))
    assert np.min(np.linalg.eigvalsh(shipped)) > -1e-9


def test_the_posterior_keeps_a_clear_look_drops_noise_and_says_how_sure_it_is():
    naturals = palette_statistics(_palettes(range(100, 160)))
    sets, singles = content_noise(naturals, 6)
    noise = sets + 0.25 * singles
    prior = load_prior()
    centre = look_differences(naturals, naturals)
    sd = np.sqrt(np.diag(noise))
    # a difference of 12 noise sd along a direction looks take: kept, and sure
    direction = prior @ np.ones(len(sd))
    direction *= 12.0 * np.linalg.norm(sd) / np.linalg.norm(direction)
    strong = posterior_look(centre.with_vector(direction), noise, prior)
    assert strong.probability > 0.99 and strong.share > 0.8
    # what content alone makes of a set: mostly dropped, and not sure
    rng = np.random.default_rng(3)
    draws = [posterior_look(centre.with_vector(rng.multivariate_normal(np.zeros(len(sd)),
                                                                       noise)), noise, prior)
             for _ in range(20)]
    assert np.median([d.share for d in draws]) < 0.3
    assert np.median([d.probability for d in draws]) < 0.7
    # the differences' vector layout round-trips, chroma with no luma
    back = centre.with_vector(centre.vector())
    assert np.allclose(back.vector(), centre.vector())
    assert isinstance(back, LookDifferences)
    assert np.allclose(back.tint @ np.array([0.2126, 0.7152, 0.0722]), 0.0, atol=1e-12)


@pytest.mark.parametrize("size", [3, 12])
def test_a_strong_look_lands_and_a_set_with_none_stays_put_from_3_to_12_photos(size):
    from tests.color.test_look_statistics import faded_teal, natural_photo
    from wbcgrade.color.look import set_extraction as look
    from wbcgrade.color.presets import StyleSet

    def style_set(images):
        return StyleSet([f"s{i}" for i in range(len(images))],
                        np.stack([image_histogram(i, 32) for i in images]),
                        meta={"cache_dir": None})

    naturals = style_set([natural_photo(s) for s in range(100, 140)])
    contents = [natural_photo(s) for s in range(size)]
    test = np.concatenate([natural_photo(s) for s in range(200, 204)])
    before = np.mean(np.abs(faded_teal(test) - test))
    base, _, strength = look.set_look_base(style_set([faded_teal(c) for c in contents]),
                                           naturals)
    assert np.mean(np.abs(base(test) - faded_teal(test))) < 0.75 * before
    plain, _, plain_strength = look.set_look_base(style_set(contents), naturals)
    assert np.mean(np.abs(plain(test) - test)) < 0.25 * before
    assert plain_strength < strength


def test_the_jackknife_keeps_a_look_every_group_shows_and_drops_one_a_group_makes_up():
    from wbcgrade.color.look.prior import jackknife_share

    colors = grid_points(5)
    masses = np.ones(len(colors))
    shift = np.array([0.05, 0.0, -0.05])

    def shifted(amount):
        return lambda x: np.clip(x + amount * shift, 0.0, 1.0)

    # every group of styles, left out, gives the same look: all of it kept
    assert jackknife_share(shifted(1.0), lambda keep: shifted(1.0), 6, colors, masses) == 1.0
    # the look appears only while one style is in: it is that style's, not the set's
    one = jackknife_share(shifted(1.0 / 6.0), lambda keep: shifted(keep[:5].sum() / 30.0
                                                                   if keep[5] else 0.0),
                          6, colors, masses)
    assert one < 0.6
    # nearly alike groups: nearly all kept, and two styles give no groups to compare
    near = jackknife_share(shifted(1.0), lambda keep: shifted(1.0 + 0.05 * keep.argmin()),
                           6, colors, masses)
    assert 0.9 < near < 1.0
    assert jackknife_share(shifted(1.0), lambda keep: shifted(0.0), 2, colors, masses) == 1.0


def test_the_jackknife_of_a_few_photos_counts_its_variance_at_its_small_sample_margin():
    """Three photos left out one by one estimate the look's variance from two degrees of
    freedom: counted twice (``(g + 1) / (g - 1)``), ten groups 11/9 times, so the same
    spread of looks keeps less of a three-photo set's look than of a larger set's."""
    from wbcgrade.color.look.prior import jackknife_share, small_sample_margin

    colors = grid_points(5)
    masses = np.ones(len(colors))
    shift = np.array([0.05, 0.0, -0.05])

    def shifted(amount):
        return lambda x: x + amount * shift

    # each photo left out moves the look by up to 0.3 of itself, evenly spread
    def spread_by(count):
        offsets = np.linspace(-0.3, 0.3, count)
        return lambda keep: shifted(1.0 + offsets[int(np.argmin(keep[:count]))])

    for count in (3, 10):
        offsets = np.linspace(-0.3, 0.3, count)
        variance = (count - 1) / count * np.sum((offsets - offsets.mean()) ** 2)
        expected = 1.0 - small_sample_margin(count) * variance
        kept = jackknife_share(shifted(1.0), spread_by(count), count, colors, masses)
        assert kept == pytest.approx(expected, abs=1e-9)
        assert kept < 1.0 - variance  # the plain 1 - V/P keeps more
    assert small_sample_margin(3) == 2.0
    assert small_sample_margin(10) == pytest.approx(11 / 9)


def test_one_odd_photo_in_a_set_without_a_look_moves_photos_less_than_without_the_jackknife():
    from tests.color.test_look_statistics import natural_photo
    from wbcgrade.color.look.prior import posterior_statistics_look
    from wbcgrade.color.look.statistics import tinted_statistics

    naturals = palette_statistics(np.stack([image_histogram(natural_photo(s), 32)
                                            for s in range(100, 140)]))
    odd = Edit(saturation=2.5, contrast=1.0)
    photos = [natural_photo(s) for s in range(6)]
    photos[0] = odd(photos[0])
    styles = tinted_statistics(np.stack([image_histogram(p, 32) for p in photos]), naturals)
    colors = grid_points(9)
    masses = np.ones(len(colors))
    plain = posterior_statistics_look(styles, naturals)
    checked = posterior_statistics_look(styles, naturals, jackknife_colors=(colors, masses))

    def size(look):
        return float(np.sqrt(np.mean((look(colors) - colors) ** 2)))

    assert checked.info["jackknife"]["saturation"] < 0.5
    assert set(plain.info["jackknife"].values()) == {1.0}
    assert size(checked) < 0.5 * size(plain) and size(plain) > 0.005
    # the same edit on every photo: a look all of them show, kept nearly whole
    shown = tinted_statistics(np.stack([image_histogram(odd(natural_photo(s)), 32)
                                        for s in range(6)]), naturals)
    kept = posterior_statistics_look(shown, naturals, jackknife_colors=(colors, masses))
    assert kept.info["jackknife"]["saturation"] > 0.9 and size(kept) > 10 * size(checked)


def test_the_posterior_covariance_is_the_gaussian_one_where_the_look_is_sure_to_be_there():
    """One slab and (nearly) no spike: prior p and noise n per statistic give the posterior
    variance p n / (p + n), whatever the raw differences."""
    from wbcgrade.color.look.statistics import BANDS, QUANTILES

    size = len(QUANTILES) + 3 * BANDS
    rng = np.random.default_rng(4)
    p, n = rng.uniform(0.5, 2.0, size), rng.uniform(0.5, 2.0, size)
    raw = LookDifferences(np.linspace(0.05, 0.95, len(QUANTILES)), np.zeros(len(QUANTILES)),
                          np.zeros(BANDS), np.zeros((BANDS, 3)))
    found = posterior_look(raw.with_vector(rng.normal(0.0, 1.0, size)), np.diag(n),
                           np.diag(p), no_look=1e-12, scales=(1.0,))
    assert np.allclose(np.diag(found.covariance), p * n / (p + n), rtol=1e-6)
    assert np.allclose(found.covariance, np.diag(np.diag(found.covariance)), atol=1e-9)
    # a spike beside it: unsure whether there is a look, the mixture spreads further
    mixed = posterior_look(raw.with_vector(np.full(size, 0.8)), np.diag(n), np.diag(p),
                           no_look=0.5, scales=(1.0,))
    assert 0.0 < mixed.probability < 1.0
    assert np.all(np.diag(mixed.covariance) > 0)
    inside = mixed.probability * p * n / (p + n)  # the slab's own share of the variance
    assert np.all(np.diag(mixed.covariance) > inside)


def test_a_look_is_checked_with_no_less_variance_than_the_posterior_leaves_it():
    """Photos that agree (their groups left out give the same look) still leave the look as
    unsure as the statistics make it: the share kept is 1 - V/P with V the posterior's."""
    from wbcgrade.color.look.prior import jackknife_share, posterior_spread

    colors = grid_points(5)
    masses = np.ones(len(colors))
    shift = np.array([0.05, 0.0, -0.05])

    def shifted(amount):
        return lambda x: x + amount * shift

    power = float(shift @ shift)
    same = jackknife_share(shifted(1.0), lambda keep: shifted(1.0), 3, colors, masses,
                           unsure=lambda: 0.25 * power)
    assert same == pytest.approx(0.75)
    # a jackknife that varies more than the posterior decides as before
    apart = jackknife_share(shifted(1.0), lambda keep: shifted(1.3 if keep[0] else 0.4), 3,
                            colors, masses, unsure=lambda: 0.01 * power)
    assert apart == jackknife_share(shifted(1.0), lambda keep: shifted(1.3 if keep[0] else 0.4),
                                    3, colors, masses)
    # the posterior's spread of a look linear in the differences: its covariance through it
    covariance = np.diag([0.04, 0.01, 0.0])
    spread = posterior_spread(lambda v: shifted(v[0] + v[1]), np.array([1.0, 0.0, 0.0]),
                              covariance, colors, masses, draws=4000)
    assert spread == pytest.approx(0.05 * power, rel=0.1)
    assert posterior_spread(lambda v: shifted(v[0]), np.ones(3), np.zeros((3, 3)), colors,
                            masses) == 0.0


def test_each_part_of_a_look_takes_its_own_size(monkeypatch):
    """A strong tint with no tone change: with one size for all parts, the tint's evidence
    lets the tone's prior grow and the tone's noise through; with a size per part the tone
    stays where its own evidence puts it, and the tint is kept as it was."""
    from wbcgrade.color.look.prior import PARTS, _parts
    from wbcgrade.color.look.statistics import BANDS, QUANTILES

    size = len(QUANTILES) + 3 * BANDS
    raw = LookDifferences(np.linspace(0.05, 0.95, len(QUANTILES)), np.zeros(len(QUANTILES)),
                          np.zeros(BANDS), np.zeros((BANDS, 3)))
    parts = _parts(raw)
    assert len(parts) == len(PARTS) and np.array_equal(np.sum(parts, axis=0), np.ones(size))
    noise, prior = np.eye(size), np.eye(size)
    tone, tint = parts[0], parts[2]
    vector = np.where(tint, 6.0, 0.0) + np.where(tone, 1.0, 0.0)  # tone: one noise sd
    tied = posterior_look(raw.with_vector(vector), noise, prior).differences.vector()
    apart = posterior_look(raw.with_vector(vector), noise, prior,
                           parts=parts).differences.vector()
    assert np.mean(apart[tint]) > 0.75 * 6.0 and np.mean(tied[tint]) > 0.75 * 6.0
    assert np.mean(apart[tone]) < 0.5 * np.mean(tied[tone])
    # one part, or every part at one scale: the tied slab exactly
    one = posterior_look(raw.with_vector(vector), noise, prior, scales=(1.0,),
                         parts=parts).differences.vector()
    assert np.allclose(one, posterior_look(raw.with_vector(vector), noise, prior,
                                           scales=(1.0,)).differences.vector())
    # a prior that ties the parts' sizes hard gives the tied slab back
    from wbcgrade.color.look import prior as look_prior

    monkeypatch.setattr(look_prior, "PART_TIE", 50.0)
    held = posterior_look(raw.with_vector(vector), noise, prior,
                          parts=parts).differences.vector()
    assert np.allclose(held, tied, atol=1e-6)
