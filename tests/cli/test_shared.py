"""The CLI's shared helpers."""

import typer
from typer.testing import CliRunner

from pushtoknow.cli.shared import command_line


def test_the_command_line_names_the_subcommand_whatever_the_program_was_called():
    """Run as `python -m pushtoknow.cli`, the reported command is still `pushtoknow …`, with
    the options given values other than their defaults and no report-display options."""
    app = typer.Typer()
    seen = []

    @app.command("evaluate-real")
    def run(
        ctx: typer.Context,
        data_dir: str,
        seed: int = typer.Option(0, "--seed"),
        markdown: str = typer.Option(None, "--markdown"),
    ):
        seen.append(command_line(ctx))

    @app.command("other")
    def other():
        pass

    res = CliRunner().invoke(
        app, ["evaluate-real", "DIR", "--seed", "3", "--markdown", "r.md"], prog_name="python -m x"
    )
    assert res.exit_code == 0, res.output
    assert seen == ["pushtoknow evaluate-real DIR --seed 3"]
