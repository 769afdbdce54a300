"""``wbcgrade look``: the look a folder of graded photos shares (``extract``), or the look
a photographer's before/after pairs show (``learn``), as a LUT or a saved grade."""

from __future__ import annotations

import json

import click

from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
    check_photo,
    table_options,
    table_rows,
)
from wbcgrade.cli.option_table import flag_of, flag_text, option

#: ``--lut-size`` of the look commands (at most 129 nodes a side).
_LUT_SIZE = click.IntRange(2, 129)


@click.group("look")
def look() -> None:
    """Looks: the colour grade a set of style photos shares, apart from their scenes
    (extract), or the one your own before/after edits show (learn)."""


@look.command("extract", cls=LazyOptionsCommand)
@click.argument("style_dir", required=False, type=click.Path(path_type=str))
@table_options("preset", help="A shipped preset name or preset file instead of STYLE_DIR.")
@table_options("output", required=True,
               help="LUT file to write (.cube or .clf: the ending names the format).")
@table_rows("lut_size", type=_LUT_SIZE)
@table_rows("lut_format", help=option("lut_format").help.replace("--lut file", "--output file"))
@table_options("look_strength")
@table_options("natural", help="The content model: a preset (.npz) of ungraded photos, or a "
                               "folder of six or more of your own ungraded photos (beside the "
                               "shipped palettes) [default: the shipped palettes].")
@table_options("working_space", help="Colour space the look is extracted and the LUT "
                                     "applied in [default: sRGB-encoded Rec.709].")
@table_options("overwrite", help="Replace an existing LUT file.")
@table_options("as_json", help="Print what was found as JSON.")
@table_options("no_cache", "max_image_pixels")
def extract(style_dir, preset, output, lut_size, lut_format, look_strength, natural,
            working_space, overwrite, as_json, no_cache):
    """Extract the look the photos in STYLE_DIR share and write it as a 3-D LUT.

    Each style photo is explained as a blend of ungraded palettes (its
    content) moved through one smooth colour map (the look: tone curves and
    a colour matrix); the map is fitted to all style photos at once.
    """
    from wbcgrade.errors import OptionError

    if (style_dir is None) == (preset is None):
        raise OptionError("give either STYLE_DIR or {preset}", "preset")
    if style_dir is not None:  # answered before numpy loads
        check_photo(style_dir, "style folder does not exist")
    from tqdm import tqdm

    from wbcgrade.cli._progress import style_progress
    from wbcgrade.color.grade.look_files import extract_look_file
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.presets import StyleSource

    source = StyleSource(style_dir, preset, HistogramCache(enabled=not no_cache))
    with style_progress() as on_style, \
            tqdm(desc="look", unit="style", disable=None, leave=False) as bar:
        def on_look(done: int, total: int) -> None:
            bar.total = total
            bar.n = done
            bar.refresh()

        found = extract_look_file(source, output, lut_size=lut_size, lut_format=lut_format,
                                  strength=look_strength, natural=natural,
                                  working_space=working_space, overwrite=overwrite,
                                  warn=lambda m: click.echo(f"Warning: {flag_text(m)}", err=True),
                                  on_style=on_style, on_look=on_look)
    if found.outcome is not None:  # its words name flags
        found.outcome = found.outcome.named(flag_of)
    if as_json:
        click.echo(json.dumps(found.as_dict(), indent=2))
        return
    outcome = found.outcome
    what = ("the preset's own look" if outcome.source.value == "preset-look"
            else f"the look {len(found.styles)} style photos share")
    strength = found.strength
    if outcome.probability is not None:  # judged jointly: the same words as apply's
        what, strength = outcome.source_words()
    from wbcgrade.color.outcome import change_words

    strength_words = "" if strength is None else f", strength {strength:.2f}"
    click.echo(f"wrote {found.lut}: {what}{strength_words}; across every "
               f"colour it moves colours {change_words(outcome.look_size)}")
    if outcome.unchanged or outcome.faint:
        state = ("it leaves colours essentially unchanged" if outcome.unchanged
                 else "a faint look")
        click.echo(f"{state}: {outcome.reason}")
        if outcome.source.value == "set-look":
            click.echo("--strength above 1 (up to 2) applies more of what was found; "
                       "`wbcgrade apply --mode palette` moves a photo's colours towards "
                       "the style photos' instead")


@look.command("learn", cls=LazyOptionsCommand)
@click.argument("before", type=click.Path(path_type=str))
@click.argument("after", type=click.Path(path_type=str))
@table_options("output", required=True,
               help="The look to write: .cube or .clf (a LUT) or .json (a saved grade); the "
                    "ending names the format.")
@table_rows("lut_size", type=_LUT_SIZE, help="Nodes per axis of the written look.")
@table_options("working_space", help="Colour space the look is learned and applied in "
                                     "[default: ACEScct when an original is raw, else "
                                     "sRGB-encoded Rec.709].")
@table_options("overwrite", help="Replace an existing output file.")
@table_options("as_json", help="Print the report as JSON.")
@table_options("max_image_pixels")
def learn(before, after, output, lut_size, working_space, overwrite, as_json):
    """Learn the look of a photographer's edits from BEFORE/AFTER pairs.

    BEFORE and AFTER are two photos, or two folders whose photos pair by
    file name (IMG_1.CR2 with IMG_1.jpg; an export's -edit or _copy ending
    does not count). Edited versions may be resized, cropped, turned by 90
    degrees or of another format. The look (tone curves, colour mixing and a
    smooth correction; black and white or toned when every edit is) is fitted to the
    pixels of all pairs and written for `apply --look`, `batch --look` and
    `video --look`. Edited photos in AFTER without an original are used too:
    they correct the look where the pairs' colours say little (one edited
    photo with its original and a folder of others is enough). Each pair that
    cannot be used is named with the reason; the others are used.
    """
    for path, side in ((before, "BEFORE"), (after, "AFTER")):  # answered before numpy loads
        check_photo(path, f"no such file or folder ({side})")
    from wbcgrade.cli._progress import learn_progress
    from wbcgrade.color.grade.look_files import learn_look_file

    with learn_progress("photos") as (on_pair, warn):
        found = learn_look_file(before, after, output, lut_size=lut_size,
                                working_space=working_space, overwrite=overwrite, warn=warn,
                                progress=on_pair)
    if as_json:
        click.echo(json.dumps(found.as_dict(), indent=2))
        return
    for pair in found.used:
        held = "" if pair.held_out is None else f", {pair.held_out:.1f} held out"
        click.echo(f"  {pair.name}: {pair.registered}; CIEDE2000 {pair.delta_e:.1f}{held}")
    kind = ("black-and-white look" if found.look.monochrome else
            "toned black-and-white look" if found.look.toned else "look")
    held = ("" if found.held_out is None else
            f", {found.held_out:.1f} with each pair held out ({found.folds}-fold)")
    learned = found.describe().replace("the look", f"the {kind}", 1)
    for words in (found.coverage_words(), found.reach_words(), found.original_to_add_words()):
        if words:
            click.echo(f"  {words}")
    click.echo(f"wrote {found.output}: {learned} "
               f"(mean CIEDE2000 after vs look(before) {found.delta_e:.1f}{held}; "
               f"{found.seconds:.1f} s)")
