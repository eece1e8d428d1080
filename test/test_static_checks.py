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


def test_mypy_reports_nothing(tmp_path):
    out = _run([str(BIN / "mypy"), "--cache-dir", str(tmp_path / "mypy_cache")])
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]


def test_noqa_lines_say_why():
    """A `noqa` silences a check; the line must say why (a comment after the code, beyond the bare marker)."""
    bare = []
    for path in ROOT.rglob("*.py"):
        if any(part in (".venv", "build", "install", "log") for part in path.relative_to(ROOT).parts):
            continue
        if path == Path(__file__).resolve():  # this file names the marker and the pattern it looks for
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if "# noqa" in line:
                tail = line.split("# noqa", 1)[1]
                reason = tail.split(":", 1)[1] if ":" in tail else ""
                words = [w for w in reason.replace(",", " ").split() if not w[:1].isupper() or not w[1:].isdigit()]
                if len(" ".join(words)) < 8:
                    bare.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert bare == [], "\n".join(bare[:40])


def test_comments_cite_no_tracker_issues():
    """Comments and docstrings cite the docs or the paper, never this project's tracker ("issue 14")."""
    import re
    pat = re.compile(r"\bissues? \d+\b", re.IGNORECASE)
    hits = []
    for path in ROOT.rglob("*.py"):
        if any(part in (".venv", "build", "install", "log") for part in path.relative_to(ROOT).parts):
            continue
        if path == Path(__file__).resolve():  # this file names the marker and the pattern it looks for
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if pat.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert hits == [], "\n".join(hits[:40])
