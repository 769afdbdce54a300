import json

from click.testing import CliRunner

from wbcgrade import __version__
from wbcgrade.cli import main


def test_version_and_help():
    runner = CliRunner()
    result = runner.invoke(main, ["--version"])
    assert result.exit_code == 0 and __version__ in result.output
    result = runner.invoke(main, ["--help"])
    assert result.exit_code == 0 and "demo" in result.output


def test_demo_recovers_weights():
    result = CliRunner().invoke(
        main, ["demo", "--size", "8", "--styles", "3", "--iterations", "15", "--json"]
    )
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["l1_error"] < 0.02
    assert len(report["fitted_weights"]) == 3


def test_bad_option_is_one_line_error_without_traceback():
    result = CliRunner().invoke(main, ["demo", "--size", "2"])
    assert result.exit_code == 2 and isinstance(result.exception, SystemExit)
    assert "Error" in result.output and "--size" in result.output


def test_library_error_becomes_one_line_message(tmp_path):
    result = CliRunner().invoke(main, ["apply", str(tmp_path / "missing.jpg"), "--preset", "warm"])
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:") and "missing.jpg" in lines[0]
