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
    """Counts per mutated file, the undetected mutants nobody argued equivalent (not-checked ones are only
    counted), and equivalence entries that name no survivor."""
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
            elif status not in ("killed", "timeout", "not checked"):
                unargued.append({"mutant": name, "status": status})
            counts[status] += 1
        files[source] = {"mutants": len(verdicts), **counts, **scores(len(verdicts), counts)}
    total = Counter()
    for c in files.values():
        total.update({k: v for k, v in c.items() if not k.startswith("score")})
    return {
        "tool": f"mutmut {version('mutmut')}",
        "command": command,
        "tests": cfg["pytest_add_cli_args_test_selection"],
        "score_definition": "(killed + timeout) / (mutants - equivalent); equivalent = argued in mutation.md; "
        "score_checked: the same over the mutants mutmut has a verdict for (not 'not checked')",
        "complete": total["not checked"] == 0,
        "files": files,
        "total": {**total, **scores(total["mutants"], total)},
        "not_killed_and_not_argued": unargued,
        "argued_but_not_a_survivor": sorted(n for n in equivalent if raw_status.get(n) != "survived"),
    }


STATUSES = ("killed", "timeout", "equivalent", "survived", "no tests", "not checked")


def scores(mutants: int, counts: Counter) -> dict[str, float]:
    detected, tested = counts["killed"] + counts["timeout"], mutants - counts["equivalent"]
    return {
        "score": round(detected / max(tested, 1), 4),
        "score_checked": round(detected / max(tested - counts["not checked"], 1), 4),
    }
