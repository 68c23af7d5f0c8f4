"""Both command lines teach: every sub-command has --help with an example, and the top-level
help (which lists sub-commands without importing them) says what each one really says."""

from __future__ import annotations

import click
import pytest
from click.testing import CliRunner

from groundstation.cli import _COMMANDS
from groundstation.cli import main as gs_main
from sysid.cli import main as sysid_main


@pytest.mark.parametrize("name", list(_COMMANDS))
def test_groundstation_subcommand_help(name):
    cmd = gs_main.get_command(click.Context(gs_main), name)
    assert cmd.get_short_help_str(limit=200) == _COMMANDS[name][1]
    res = CliRunner().invoke(gs_main, [name, "--help"])
    assert res.exit_code == 0 and "Usage:" in res.output
    assert "xample" in res.output or isinstance(cmd, click.Group)


def test_top_level_help_lists_every_command():
    res = CliRunner().invoke(gs_main, ["--help"])
    assert res.exit_code == 0
    assert all(name in res.output for name in _COMMANDS)
    assert CliRunner().invoke(gs_main, ["nope"]).exit_code == 2


@pytest.mark.parametrize("name", ["identify", "compare", "order", "sweep", "export"])
def test_sysid_subcommand_help_has_an_example(name):
    res = CliRunner().invoke(sysid_main, [name, "--help"])
    assert res.exit_code == 0 and "xample" in res.output


@pytest.mark.parametrize(("main", "args", "where"), [
    (gs_main, ["fly", "--bogus"], "groundstation fly -h"),
    (gs_main, ["plan", "check"], "groundstation plan check -h"),
    (gs_main, ["nope"], "groundstation -h"),
    (sysid_main, ["identify", "--bogus"], "sysid identify -h"),
    # a required choice left out: click listed the choices on lines of their own
    (gs_main, ["export", "s.h5"], "groundstation export -h"),
    (sysid_main, ["export", "model.h5"], "sysid export -h"),  # no --format, no --out to tell
])
def test_usage_errors_are_one_line_exit_2_on_both_clis(main, args, where):
    res = CliRunner().invoke(main, args, prog_name=where.split()[0])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and f"(see '{where}')" in lines[0]
    assert "Usage:" not in res.output and "Traceback" not in res.output


@pytest.mark.parametrize(("main", "args", "line"), [
    (sysid_main, ["identify", "f.h5", "-v"],
     "error: -v is an option of 'sysid', given before the command: sysid -v identify ..."),
    (gs_main, ["info", "f.h5", "--verbose"], "error: --verbose is an option of 'groundstation', "
                                             "given before the command: groundstation "
                                             "--verbose info ..."),
])
def test_a_group_option_after_the_command_says_where_it_goes(main, args, line):
    res = CliRunner().invoke(main, args, prog_name=line.split()[-4])
    assert res.exit_code == 2 and res.stderr.strip() == line, res.output
