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


def test_method_table_counts_estimates_outside_their_interval():
    from pushtoknow.reporting.results import method_table

    cells = {k: 0.1 for k in ("mass", "friction", "com_x", "com_y", "inertia", "overall")}

    def method(outside: int | None) -> dict:
        m = {"nrmse": cells, "nrmse_std": cells, "mu_m": 0.05, "mu_m_std": 0.01}
        m |= {"coverage68": 0.7, "coverage90": 0.9, "estimates": 12}
        return m | {"impossible_estimates": 0, "outside_interval": outside}

    lines = method_table({"filter": method(3), "old": method(None)}).splitlines()
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    rows = {
        r[0]: r for r in ([c.strip() for c in line.strip("|").split("|")] for line in lines[2:])
    }
    col = header.index("outside interval")
    assert header[col - 1] == "impossible"
    assert rows["filter"][col] == "3/12" and rows["filter"][col - 1] == "0/12"
    assert rows["old"][col] == "–"  # a run without intervals


def test_a_report_names_no_folder_of_the_machine_that_made_it(tmp_path, monkeypatch):
    from pushtoknow.reporting.results import shown_path

    monkeypatch.chdir(tmp_path)
    assert shown_path(str(tmp_path / "runs" / "model")) == "runs/model"
    assert shown_path("/elsewhere/deep/pretrained/vt-addf") == "pretrained/vt-addf"
