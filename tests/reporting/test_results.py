"""The generated report's tables."""

from pushtoknow.reporting.results import coverage_by_push_table


def _method(first: float, last: float, pushes: int = 3) -> dict:
    rows = [{"coverage90": {k: first for k in ("mass", "friction", "com_x", "com_y", "inertia")}}]
    rows += [dict(rows[0]) for _ in range(pushes - 2)]
    rows.append(
        {"coverage90": {k: last for k in ("mass", "friction", "com_x", "com_y", "inertia")}}
    )
    return {"per_push": [{"coverage90": {}}, *rows]}


def test_coverage_by_push_shows_the_first_and_the_last_push_of_each_full_run():
    methods = {
        "filter": _method(0.8, 0.9),
        "oracle": {"per_push": [{"coverage90": {}}, {"coverage90": {}}]},  # final only
    }
    lines = coverage_by_push_table(methods).splitlines()
    assert "m, push 1" in lines[0] and "I_z, push 3" in lines[0]
    assert len(lines) == 3  # header, rule, one method: the oracle has no push 1
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    assert cells == ["filter", *["0.80"] * 5, *["0.90"] * 5]
