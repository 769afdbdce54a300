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
    assert result.exit_code != 0
    assert "Traceback" not in result.output
