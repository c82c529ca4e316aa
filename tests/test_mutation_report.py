"""The mutation report counts mutmut's verdicts per file and takes argued-equivalent survivors out."""

import json

import pytest

pytest.importorskip("mutmut")

from benchmarks.mutation.report import mutation_report  # noqa: E402

CORE = "pkg/core.py"


def test_counts_verdicts_and_only_argued_survivors_are_equivalent(tmp_path):
    (tmp_path / "pyproject.toml").write_text(
        f'[tool.mutmut]\nonly_mutate = ["{CORE}"]\npytest_add_cli_args_test_selection = ["tests/t.py"]\n'
    )
    names = [f"pkg.core.x_f__mutmut_{i}" for i in range(1, 7)]
    verdicts = dict(
        zip(names, [1, 1, 0, 0, 36, None], strict=True)
    )  # killed x2, survived x2, timeout, unchecked
    meta = tmp_path / "mutants" / f"{CORE}.meta"
    meta.parent.mkdir(parents=True)
    meta.write_text(json.dumps({"exit_code_by_key": verdicts}))
    markdown = tmp_path / "mutation.md"
    markdown.write_text(
        f"| mutant | why |\n|---|---|\n| `{names[2]}` | same value |\n| `{names[0]}` | stale |\n"
    )
    report = mutation_report(tmp_path, markdown, "make mutation")
    counts = report["files"][CORE]
    assert {k: counts[k] for k in ("killed", "survived", "equivalent", "timeout", "not checked")} == {
        "killed": 2,
        "survived": 1,
        "equivalent": 1,
        "timeout": 1,
        "not checked": 1,
    }
    assert counts["score"] == pytest.approx(3 / 5) and counts["score_checked"] == pytest.approx(3 / 4)
    assert report["not_killed_and_not_argued"] == [{"mutant": names[3], "status": "survived"}]
    assert report["argued_but_not_a_survivor"] == [names[0]]
