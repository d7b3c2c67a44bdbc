"""The docs are current reference, not a lab notebook (issue 36): no dated entries, no
"this session" / "this branch", no commit hashes, no before/after history sections. History
lives in git."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

PATTERNS = {
    "a session or branch": re.compile(r"\b(this|last|previous) (session|branch)\b", re.I),
    "a history section": re.compile(r"^#+ .*\b(history|changelog|before and after)\b", re.I),
    "a before/after comparison": re.compile(
        r"\bbefore \((main|this)\b|\b(before|after) the [\w-]+( [\w-]+)? (work|changes?)\b"
    ),
    "a dated entry": re.compile(r"^\s*(#+ |[-*] |\| )?\**20\d\d-[01]\d-[0-3]\d\b(?!T)"),
    # 7-40 hex digits with a letter and a digit, not a 0x number: a commit
    "a commit hash": re.compile(
        r"(?<![0-9A-Za-z_x/.-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![0-9A-Za-z_])"
    ),
}


def findings(text: str) -> list[str]:
    return [
        f"{n}: {what}: {line.strip()[:80]}"
        for n, line in enumerate(text.splitlines(), 1)
        for what, pattern in PATTERNS.items()
        if pattern.search(line)
    ]


def test_docs_hold_no_dated_history() -> None:
    bad = [
        f"{path.relative_to(ROOT)}:{f}"
        for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
        for f in findings(path.read_text(encoding="utf-8"))
    ]
    assert not bad, "history in the docs (it lives in git):\n" + "\n".join(bad)


def test_the_check_sees_a_notebook() -> None:
    notebook = (
        "## History\n"
        "- 2026-11-02: tracking 3x faster\n"
        "Measured on this branch (9e7d7e8), before (main) and after.\n"
        "| seed 1, before the late-detection work | 12 |\n"
    )
    kinds = {f.split(": ")[1] for f in findings(notebook)}
    assert kinds == set(PATTERNS)
    reference = "Epoch 2026-01-01T00:00:00Z; frame 0x1000000 | 7FFFFF; sysid 3434009.\n"
    assert findings(reference) == []
