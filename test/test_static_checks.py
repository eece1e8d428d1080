"""Static checks as part of the tests, as ament_flake8 / ament_pep257 / ament_mypy are for ROS packages.

ruff (pyflakes, pycodestyle, import order, docstrings of public definitions; ruff.toml) over the whole checkout
and mypy (setup.cfg's [mypy]) over the six packages must report nothing.
"""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent


def _run(argv: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=600)


def test_ruff_reports_nothing():
    out = _run([str(BIN / "ruff"), "check", "--no-cache", "."])
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]


def test_mypy_reports_nothing():
    """mypy's incremental cache in the checkout's .cache/ (git-ignored): a rerun checks only what changed (20 s -> a
    few s); a fresh clone builds it."""
    out = _run([str(BIN / "mypy"), "--cache-dir", str(ROOT / ".cache" / "mypy")])
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]


def _source_lines():
    """(path relative to the checkout, line number, line) of every Python file of the checkout but this one (it
    names the marker and the pattern it looks for) and the venv / colcon folders."""
    for path in ROOT.rglob("*.py"):
        rel = path.relative_to(ROOT)
        if any(part in (".venv", "build", "install", "log") for part in rel.parts) or path == Path(__file__).resolve():
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            yield rel, i, line


def test_noqa_lines_say_why():
    """A `noqa` silences a check; the line must say why (a comment after the code, beyond the bare marker)."""
    bare = []
    for rel, i, line in _source_lines():
        if "# noqa" in line:
            tail = line.split("# noqa", 1)[1]
            reason = tail.split(":", 1)[1] if ":" in tail else ""
            words = [w for w in reason.replace(",", " ").split() if not w[:1].isupper() or not w[1:].isdigit()]
            if len(" ".join(words)) < 8:
                bare.append(f"{rel}:{i}: {line.strip()}")
    assert bare == [], "\n".join(bare[:40])


def test_comments_cite_no_tracker_issues():
    """Comments and docstrings cite the docs or the paper, never this project's tracker (an issue number)."""
    import re
    pat = re.compile(r"\bissues? \d+\b", re.IGNORECASE)
    hits = [f"{rel}:{i}: {line.strip()}" for rel, i, line in _source_lines() if pat.search(line)]
    assert hits == [], "\n".join(hits[:40])
