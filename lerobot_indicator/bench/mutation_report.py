"""Per-file mutation-testing counts from a finished ``mutmut run`` (``make mutation``).

mutmut keeps one verdict (a pytest exit code) per mutant in ``mutants/<source>.meta``. Survivors that are
argued equivalent are listed by name in the first column of the survivors table of ``mutation.md``
(``| `lerobot_indicator...__mutmut_N` | ... |``); the score is (killed + timed out) / (all - equivalent),
mutmut's own definition with the argued-equivalent mutants taken out of the denominator.
"""

from __future__ import annotations

import json
import re
import tomllib
from collections import Counter
from importlib.metadata import version
from pathlib import Path

from mutmut.stats import status_by_exit_code

EQUIVALENT_ROW = re.compile(r"^\|\s*`([\w.ǁ]+__mutmut_\d+)`\s*\|", re.MULTILINE)


def equivalent_mutants(markdown: Path) -> set[str]:
    """Mutant names in the first column of ``markdown``'s tables."""
    return set(EQUIVALENT_ROW.findall(markdown.read_text())) if markdown.is_file() else set()


def mutation_report(repo: Path, markdown: Path, command: str) -> dict:
    """Counts per mutated file, the survivors nobody argued equivalent, and stale equivalence entries."""
    cfg = tomllib.loads((repo / "pyproject.toml").read_text())["tool"]["mutmut"]
    equivalent = equivalent_mutants(markdown)
    files, unargued, raw_status = {}, [], {}
    for source in cfg["only_mutate"]:
        meta = repo / "mutants" / f"{source}.meta"
        if not meta.is_file():
            raise FileNotFoundError(f"{meta} is missing: run `mutmut run` first (make mutation)")
        verdicts = json.loads(meta.read_text())["exit_code_by_key"]
        counts = Counter({k: 0 for k in STATUSES})
        for name, exit_code in verdicts.items():
            status = raw_status[name] = status_by_exit_code[exit_code]
            if status == "survived" and name in equivalent:
                status = "equivalent"
            elif status not in ("killed", "timeout"):
                unargued.append({"mutant": name, "status": status})
            counts[status] += 1
        files[source] = {"mutants": len(verdicts), **counts, "score": score(len(verdicts), counts)}
    total = Counter()
    for c in files.values():
        total.update({k: v for k, v in c.items() if k != "score"})
    return {
        "tool": f"mutmut {version('mutmut')}",
        "command": command,
        "tests": cfg["pytest_add_cli_args_test_selection"],
        "score_definition": "(killed + timeout) / (mutants - equivalent); equivalent = argued in mutation.md",
        "files": files,
        "total": {**total, "score": score(total["mutants"], total)},
        "not_killed_and_not_argued": unargued,
        "argued_but_not_a_survivor": sorted(n for n in equivalent if raw_status.get(n) != "survived"),
    }


STATUSES = ("killed", "timeout", "equivalent", "survived", "no tests", "not checked")


def score(mutants: int, counts: Counter) -> float:
    return round((counts["killed"] + counts["timeout"]) / max(mutants - counts["equivalent"], 1), 4)
