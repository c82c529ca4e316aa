"""Code and docs say what a thing is and why, never its history: no references to internal work sessions
("stop N") or to how things were before, which rot and mean nothing to a reader. Results docs hold the
current tables and the commands that made them; superseded runs are deleted (git keeps them).

The patterns are built from pieces so this file does not match itself.
"""

import io
import re
import shutil
import subprocess
import tokenize
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SESSION = "st" + "op"  # an internal work session, never explained to a reader
SESSION_N = rf"\b{SESSION}[ -]?\d+"  # "<session> 14", "<session>-12", "<session> 13's"
HISTORY = re.compile(
    "|".join(
        [
            SESSION_N,
            rf"\b(this|last|previous|next|that) {SESSION}\b",
            r"\bbefore the " + "fix" + r"\b",
            r"\bearlier " + "default" + r"\b",
            r"\bwas computed " + "by hand" + r"\b",
            r"\(" + "was ",
        ]
    ),
    re.IGNORECASE,
)
SESSION_IN_TESTS = re.compile(SESSION_N, re.IGNORECASE)


def tracked_files() -> list[str]:
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    out = subprocess.run(
        ["git", "-C", str(REPO), "ls-files", "-z"], check=True, capture_output=True, text=True
    ).stdout
    return [f for f in out.split("\0") if f]


def text_of(path: str) -> str | None:
    try:
        data = (REPO / path).read_bytes()
    except (FileNotFoundError, IsADirectoryError):  # deleted in the work tree, or a submodule
        return None
    if b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def test_no_history_words_outside_tests():
    hits = []
    for path in tracked_files():
        if path.startswith("tests/"):
            continue
        text = text_of(path)
        if text is None:
            continue
        for lineno, line in enumerate(text.splitlines(), 1):
            match = HISTORY.search(line)
            if match:
                hits.append(f"{path}:{lineno}: {match.group(0)!r} in {line.strip()[:120]!r}")
    assert not hits, "history phrases (say what and why instead):\n" + "\n".join(hits)


def test_no_work_session_numbers_in_test_comments():
    hits = []
    this_file = Path(__file__).relative_to(REPO).as_posix()
    for path in tracked_files():
        if not (path.startswith("tests/") and path.endswith(".py")) or path == this_file:
            continue
        text = text_of(path)
        if text is None:
            continue
        for token in tokenize.generate_tokens(io.StringIO(text).readline):
            if token.type == tokenize.COMMENT and SESSION_IN_TESTS.search(token.string):
                hits.append(f"{path}:{token.start[0]}: {token.string.strip()[:120]!r}")
    assert not hits, "work-session references in test comments:\n" + "\n".join(hits)


@pytest.mark.parametrize(
    "line",
    [
        "the default before " + SESSION + " 14",
        "Rerun in " + SESSION + " 12 after the fix",
        "as " + SESSION + "-12 showed",
        SESSION.capitalize() + " 13's reading",
        "Until this " + SESSION + " the trainer froze",
        "caused last " + SESSION + "'s plateau",
        "3000 before the " + "fix",
        "first_cycle (the earlier " + "default)",
        "a column (was computed " + "by hand)",
        "batch 64 (" + "was 128)",
    ],
)
def test_pattern_catches_history(line):
    assert HISTORY.search(line)


@pytest.mark.parametrize(
    "line",
    ["early stopping", "the pusher stops at the rope", "stop_gradient", "the loop stops after 3 pushes"],
)
def test_pattern_spares_ordinary_words(line):
    assert not HISTORY.search(line)
