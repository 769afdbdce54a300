"""The one option table (wbcgrade/cli/option_table.py): click options, JSON keys and the
error names come from it, and every bad option exits 2."""

import click
import pytest
from click.testing import CliRunner

from wbcgrade.cli import USAGE_ERROR, main
from wbcgrade.cli.option_table import OPTIONS, flag_error, flag_of
from wbcgrade.color.options import FLAT_FIELDS, GradeOptions, flat_defaults
from wbcgrade.errors import OptionError


def _params(command: str) -> dict[str, click.Parameter]:
    group = main.commands[command]
    return {p.name: p for p in group.get_params(click.Context(group))}


@pytest.mark.parametrize("row", [r for r in OPTIONS if r.json is not None],
                         ids=lambda r: r.name)
def test_a_rows_json_key_is_the_libraries_flat_name_of_its_field(row):
    group, name = FLAT_FIELDS[row.json]
    assert row.field == f"{group}.{name}"
    assert row.json in GradeOptions().flat()


@pytest.mark.parametrize("command", ["apply", "batch", "report", "video"])
def test_the_commands_options_are_the_tables_rows(command):
    params = _params(command)
    rows = [r for r in OPTIONS if r.name in params]
    assert len(rows) >= 20
    for row in rows:
        assert row.flag in params[row.name].opts, (command, row.name)
        if row.json is not None and row.default is not None and not row.is_flag:
            assert params[row.name].default == flat_defaults()[row.json], row.name


@pytest.mark.parametrize("command", ["apply", "batch", "report", "video"])
def test_every_option_of_a_grading_command_is_a_table_row(command):
    names = {row.name for row in OPTIONS}
    params = _params(command)
    # (the help option's own name differs between click versions: it is left out by its flag)
    options = {name for name, p in params.items()
               if isinstance(p, click.Option) and "--help" not in p.opts}
    assert options - names == set()


def test_a_required_row_stays_required(tmp_path):
    result = CliRunner().invoke(main, ["batch", str(tmp_path), "--preset", "warm"])
    assert result.exit_code == 2 and "Missing option '-o' / '--output-dir'" in result.output


def test_video_has_the_tables_video_settings():
    params = _params("video")
    for name in ("sample_every", "cut_threshold", "blend_frames", "codec", "crf"):
        assert params[name].opts == [flag_of[next(r.field for r in OPTIONS if r.name == name)]]


@pytest.mark.parametrize("field, message, shown", [
    ("transfer.bins", "{transfer.bins} must be between 4 and 256",
     "--bins must be between 4 and 256"),
    ("map.strength", "{map.strength} must be in [0, 4]", "--strength must be in [0, 4]"),
    ("lut_format", "out.cube: LUT file name must end in .clf ({lut_format} clf)",
     "out.cube: LUT file name must end in .clf (--lut-format clf)"),
])
def test_library_errors_name_fields_and_the_cli_their_flags(field, message, shown):
    library = OptionError(message, field)
    assert str(library) == message.replace("{", "").replace("}", "")  # the field, in words
    error = flag_error(library)
    assert str(error) == shown and error.option == flag_of[field]


def test_other_settings_a_message_names_become_flags_too():
    error = flag_error(OptionError("{lut} needs {consistent} (one grade); `apply --lut` writes "
                                   "per-photo LUTs", "lut", also=("consistent",)))
    assert str(error) == ("--lut needs --consistent (one grade); `apply --lut` writes "
                          "per-photo LUTs")


@pytest.mark.parametrize("args", [
    ["--mode", "palette", "--bins", "3"],   # the library's range (exited 1 before)
    ["--strength", "9"],
    ["--mode", "palette", "--weights", "1,x"],
    ["--working-space", "no-such-space"],
    ["--bins", "64"],                       # a palette option without --mode palette
    ["--quality", "0"],                     # click's own range check
])
def test_every_bad_option_exits_2_naming_its_flag(tmp_path, args):
    result = CliRunner().invoke(main, ["apply", str(tmp_path / "missing.jpg"), "--preset",
                                       "warm", *args])
    assert result.exit_code == USAGE_ERROR == 2, result.output
    assert args[-2] in result.output


def test_a_field_has_one_flag():
    flags = {}
    for row in OPTIONS:
        if row.field is not None:
            assert flags.setdefault(row.field, row.flag) == row.flag, row.field


@pytest.mark.parametrize("command", [("look", "extract"), ("look", "learn"), ("preset", "build"),
                                     ("preset", "list"), ("explore",), ("brdf", "synth"),
                                     ("brdf", "fit"), ("shape", "complete"),
                                     ("shape", "project")])
def test_the_other_commands_options_are_table_rows(command):
    group = main
    for name in command:
        group = group.commands[name]
    params = {p.name: p for p in group.get_params(click.Context(group))
              if isinstance(p, click.Option) and "--help" not in p.opts}
    rows = {row.name: row for row in OPTIONS}
    assert set(params) - set(rows) == set()
    for name, param in params.items():
        if name in rows:
            assert rows[name].flag in param.opts, (command, name)


@pytest.mark.parametrize("error, shown", [
    # the path the message starts with is never rewritten, even when it holds the field's name
    (OptionError("codec/out.mp4: {codec} prores needs one of .mov, .mkv", "codec",
                 path="codec/out.mp4"), "codec/out.mp4: --codec prores needs one of .mov, .mkv"),
    (OptionError("codec: {codec} prores needs .mov", "codec", path="codec"),
     "codec: --codec prores needs .mov"),
    # without a path, only the setting written in braces is the setting
    (OptionError("out/codec/x.mp4 and {codec} prores", "codec"),
     "out/codec/x.mp4 and --codec prores"),
])
def test_a_path_in_a_message_keeps_its_names(error, shown):
    assert str(flag_error(error)) == shown


@pytest.mark.parametrize("args, shown", [
    (["apply", "p.jpg", "--preset", "warm", "--lut", "out.txt"], "--lut file name"),
    (["video", "clip.mp4", "--preset", "warm", "--codec", "prores", "-o", "codec/out.mp4"],
     "codec/out.mp4: --codec prores"),
    (["video", "clip.mp4", "--preset", "warm", "--lut", "out.txt"], "--lut file name"),
    (["preset", "build", "styles", "-o", "x.npz", "--width", "-1"], "--width must be"),
    (["preset", "build", "styles", "-o", "x.npz", "--bins", "3"], "--bins must be"),
    (["preset", "build", "styles", "-o", "x.txt"], "--output file name must end in .npz"),
    (["look", "extract", "--preset", "warm", "-o", "out.txt"], "--output file name"),
    (["look", "extract", "-o", "out.cube"], "give either STYLE_DIR or --preset"),
    (["look", "learn", "p.jpg", "p.jpg", "-o", "out.txt"], "--output must be written as"),
    (["explore", "p.jpg"], "give exactly one of --style DIR or --preset"),
    (["brdf", "synth", "-o", "db", "--material", "nosuch"], "--material 'nosuch' is unknown"),
    (["brdf", "fit", "p.jpg", "--database", "styles", "--width", "0"], "'--width'"),
    (["brdf", "fit", "p.jpg", "--database", "styles", "--keep", "0"], "'--keep'"),
    (["brdf", "fit", "p.jpg", "--database", "styles", "--loss", "kl_reverse"], "'--loss'"),
    (["shape", "complete", "p.ply", "-d", "styles", "--iterations", "0"], "'--iterations'"),
    (["shape", "complete", "p.ply", "-d", "styles", "--width", "0.1"], "'--width'"),
    (["shape", "project", "p.npy", "-d", "styles", "--loss", "sinkhorn-divergence"],
     "'--loss'"),
    (["shape", "project", "p.npy", "-d", "styles", "--missing", "1"], "'--missing'"),
    (["shape", "complete", "p.ply", "-d", "styles", "-o", "x.txt"],
     "x.txt: the --output mesh must end in"),
    (["shape", "project", "p.npy", "-d", "styles", "-o", "x.txt"],
     "x.txt: the --output volume must end in"),
])
def test_a_bad_option_of_any_command_exits_2_naming_its_flag(tmp_path, monkeypatch, args,
                                                             shown):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "styles").mkdir()
    (tmp_path / "codec").mkdir()
    (tmp_path / "clip.mp4").write_bytes(b"x")
    for name in ("p.jpg", "p.ply", "p.npy"):
        (tmp_path / name).write_bytes(b"x")
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert shown in result.output.strip().splitlines()[-1]


def test_a_missing_input_file_is_not_an_option_error(tmp_path):
    database = tmp_path / "db"
    assert CliRunner().invoke(main, ["brdf", "synth", "-o", str(database), "--count", "1"]
                              ).exit_code == 0
    for args in (["apply", str(tmp_path / "missing.jpg"), "--preset", "warm"],
                 ["video", str(tmp_path / "missing.mp4"), "--preset", "warm"],
                 ["brdf", "fit", str(tmp_path / "missing.binary"), "--database",
                  str(database)],
                 ["shape", "complete", str(tmp_path / "missing.ply"), "-d", str(tmp_path)],
                 ["shape", "project", str(tmp_path / "missing.npy"), "-d", str(tmp_path)]):
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 1 and "no such" in result.output.lower(), result.output


def test_a_missing_brdf_database_is_an_input_error(tmp_path):
    (tmp_path / "m.binary").write_bytes(b"x")
    result = CliRunner().invoke(main, ["brdf", "fit", str(tmp_path / "m.binary"), "--database",
                                       str(tmp_path / "nodb")])
    assert result.exit_code == 1, result.output


@pytest.mark.parametrize("command, name, default", [
    (("brdf", "fit"), "brdf_width", "wbcgrade.brdf.defaults:DEFAULT_WIDTH"),
    (("brdf", "fit"), "brdf_n_iter", "wbcgrade.brdf.defaults:DEFAULT_N_ITER"),
    (("brdf", "fit"), "brdf_loss", "wbcgrade.brdf.defaults:DEFAULT_LOSS"),
    (("brdf", "synth"), "directions", "wbcgrade.brdf.defaults:DEFAULT_DIRECTIONS"),
    (("shape", "complete"), "shape_iterations", "wbcgrade.shape.defaults:DEFAULT_N_ITER"),
    (("shape", "project"), "shape_max_iter", "wbcgrade.shape.defaults:DEFAULT_MAX_ITER"),
    (("shape", "project"), "resolution", "wbcgrade.shape.defaults:DEFAULT_RESOLUTION"),
    (("shape", "complete"), "shape_loss", "wbcgrade.shape.defaults:DEFAULT_LOSS"),
])
def test_brdf_and_shape_defaults_are_the_librarys(command, name, default):
    from importlib import import_module

    group = main
    for part in command:
        group = group.commands[part]
    params = {p.name: p for p in group.get_params(click.Context(group))}
    module, attr = default.split(":")
    assert params[name].default == getattr(import_module(module), attr)


def test_a_scheduler_without_dask_is_an_option_error(monkeypatch):
    import sys

    from wbcgrade._executor import _dask_client

    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    with pytest.raises(OptionError, match="scheduler needs Dask") as caught:
        _dask_client("tcp://127.0.0.1:1")
    assert str(flag_error(caught.value)).startswith("--scheduler needs Dask")


def test_an_input_errors_hint_names_the_flag_and_still_exits_1(tmp_path):
    import pickle

    from wbcgrade.errors import InputError

    folder = tmp_path / "recursive"  # a folder named like the setting keeps its name
    folder.mkdir()
    result = CliRunner().invoke(main, ["batch", str(folder), "--preset", "warm", "-o",
                                       str(tmp_path / "out")])
    assert result.exit_code == 1, result.output
    assert result.output.strip().splitlines()[-1] == (
        f"Error: {folder}: no photos found (use --recursive for sub-folders)")
    error = pickle.loads(pickle.dumps(InputError("a: b", fields=("recursive",), path="a")))
    assert (error.fields, error.path) == (("recursive",), "a")
