#!/usr/bin/env python
"""Write docs/results/mutation.json from a finished ``mutmut run`` (``make mutation`` runs both).

    python -m benchmarks.mutation.run [--markdown docs/results/mutation.md] [--out docs/results/mutation.json]

Survivors argued equivalent are read from the survivors table of ``--markdown``; see
``benchmarks/mutation/report.py``.
"""

import argparse
import json
from pathlib import Path

from benchmarks.mutation.report import mutation_report

REPO = Path(__file__).resolve().parents[2]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--markdown", type=Path, default=REPO / "docs" / "results" / "mutation.md")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "results" / "mutation.json")
    parser.add_argument(
        "--command", default="make mutation", help="the command that ran mutmut, for the report"
    )
    args = parser.parse_args()
    report = mutation_report(REPO, args.markdown, args.command)
    args.out.write_text(json.dumps(report, indent=2, ensure_ascii=False) + "\n")
    print(json.dumps(report["total"]))
    for row in report["not_killed_and_not_argued"]:
        print(f"not killed, not argued equivalent: {row['mutant']} ({row['status']})")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
