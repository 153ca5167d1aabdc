"""`pushtoknow bench`'s printing: the accuracy summary both accuracy benches print."""

from types import SimpleNamespace

from pushtoknow.common.params import PARAM_NAMES


def test_the_accuracy_summary_prints_every_parameter_and_the_overall_error(monkeypatch):
    from rich.console import Console

    from pushtoknow.cli import bench

    console = Console(record=True, width=200)
    monkeypatch.setattr(bench, "console", console)
    errors = dict(zip(PARAM_NAMES, (0.011, 0.022, 0.033, 0.044, 0.555), strict=True))
    coverage = dict(zip(PARAM_NAMES, (1.0, 0.5, 0.25, 0.0, 0.75), strict=True))
    summary = SimpleNamespace(error_norm_mean=errors, coverage90=coverage, error_norm_overall=0.133)
    bench._print_accuracy_summary(summary)
    lines = console.export_text().splitlines()
    for p in PARAM_NAMES:
        [row] = [line for line in lines if line.split("│")[1:2] and line.split("│")[1].strip() == p]
        assert f"{errors[p]:.3f}" in row and f"{coverage[p]:.2f}" in row
    assert any("overall" in line and "0.133" in line for line in lines)
