"""Smoke test of the filter benchmark (tiny sizes; the real numbers come from the CLI)."""

from pushtoknow.bench.filter import run_filter_bench


def test_run_filter_bench_reports_both_variants():
    out = run_filter_bench(seed=0, batch=2, sigma_points=12, repeats=1, num_threads=1)
    assert out.step_ms_median > 0 and out.object_steps_per_s > 0
    assert isinstance(out.machine, str) and out.machine
    assert set(out.variants) == {"mean_crop32", "per_sigma_full64"}
    for v in out.variants.values():
        assert v["step_ms_median"] > 0 and v["object_steps_per_s"] > 0
