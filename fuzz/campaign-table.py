#!/usr/bin/env python3
"""Prints the README's table of the long campaign from fuzz/campaign/figures.tsv: per target
(in bounds.sh's order) its total of inputs and each run, so that the README says what the
recorded runs say and nothing else.

    python3 fuzz/campaign-table.py            # the table, to paste under "### The long campaign"
    python3 fuzz/campaign-table.py --check README.md   # fails when the README's table differs
"""
import csv
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TOTAL = 10_000_000


def targets() -> list:
    text = (HERE / "bounds.sh").read_text()
    return re.search(r"^fuzz_targets=\(([^)]*)\)", text, re.M).group(1).split()


def number(v: str) -> str:
    return f"{int(v):,}" if v.isdigit() else v


def started(v: str) -> str:
    # Runs started at a whole minute were noted to the minute.
    return re.sub(r"(\d\d:\d\d):00$", r"\1", v.replace("T", " ").rstrip("Z"))


def table() -> str:
    with (HERE / "campaign" / "figures.tsv").open(newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    lines = [
        "| target | inputs in all (of 10,000,000) | runs: inputs, seconds, inputs/s, started (UTC), result |",
        "|---|---|---|",
    ]
    for target in targets():
        runs = [r for r in rows if r["target"] == target]
        total = sum(int(r["inputs"]) for r in runs if r["inputs"].isdigit())
        done = f"{total:,} (done)" if total >= TOTAL else f"{total:,}"
        described = "; ".join(
            f"{number(r['inputs'])}, {number(r['seconds'])} s, {number(r['inputs_per_s'])}/s, "
            f"{started(r['started_utc'])}, {r['result']}"
            for r in runs
        )
        lines.append(f"| `{target}` | {done} | {described or 'no run yet'} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    made = table()
    if len(sys.argv) == 3 and sys.argv[1] == "--check":
        readme = Path(sys.argv[2]).read_text()
        if made not in readme:
            sys.exit(f"{sys.argv[2]}: the campaign table differs from figures.tsv; "
                     "paste the output of fuzz/campaign-table.py")
        return
    sys.stdout.write(made)


if __name__ == "__main__":
    main()
