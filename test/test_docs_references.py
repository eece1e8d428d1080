"""The docs, config and code say what the system is, and every reference in them resolves inside the repository.

(a) No tracker numbers or work-history labels (a tracker's "issue" with a number, a work session's "stop" or
    "round" with a number) in docs/, config/, README.md or the project's code; an upstream project's issue named
    as `name#123` (the bug a workaround works around) is a reference and stays. CHANGELOG.md is history by design.
(b) Every relative markdown link (and its #anchor) in docs/ and README.md, and every repository path (`dir/file.ext`
    whose first component is a top-level entry of the checkout) or dotted module path (`package.module.name`)
    named in docs/, README.md, config/ or the code resolves: the file exists, the module exists and defines the
    name, and a section cited by its heading (`docs/x.md, "Heading"`) or number (`section 6`) is one of that
    document's headings. Notes files outside the repository (`../x`, `STACK-NOTES`) are unresolved references.
Text only, no imports of the project: well under a second.
"""
import re
from functools import lru_cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SELF = Path(__file__).resolve()
# Generated or machine-local folders (git-ignored): not the repository's content.
SKIP_DIRS = {".git", ".venv", "build", "install", "log", "out", ".cache", "__pycache__", ".pytest_cache",
             ".hypothesis", ".ros"}
TEXT_SUFFIXES = {".md", ".py", ".c", ".h", ".msg", ".srv", ".action", ".yaml", ".yml", ".xml", ".toml", ".cfg",
                 ".ini", ".sh", ".txt", ".dot", ".cmake", ".jsonl", ".json", ".csv", ""}
CODE_SUFFIXES = {".py", ".c", ".h", ".msg", ".srv", ".action", ".xml", ".toml", ".cfg", ".ini", ".sh", ".cmake", ""}

HISTORY = re.compile(
    r"\bissues?[ _-]*#?\s*\d+"  # a tracker's issue with its number: "issue #14", "issue-14"
    r"|(?<!--)\b(?:stop|round|session|sprint|milestone)[ _-]?#?\d+\b"  # "stop 32", "stop-33", "stop33"
    r"|\b(?:stops|rounds|sessions) \d+ ?[-–] ?\d+\b"  # "stops 32-33"
    r"|(?<![\w/.-])#\d{1,5}\b"  # a bare "#14"; an upstream "rclpy#1452" has its project's name in front
    r"|\b(?:this|that|last|next|previous|the final main of|before|after) (?:stop|round|session|sprint)\b"
    r"|\b(?:PR|pull request|ticket) ?#?\d+",
    re.IGNORECASE)
KEYWORD = re.compile(r"\b(?:issue|stop|round|session|sprint|milestone|ticket|pull|(?-i:PR))|#\d", re.IGNORECASE)


def _files(top: Path = ROOT):
    """Every file of the checkout but the generated folders, the egg-info and this test (it spells the patterns)."""
    for path in sorted(top.rglob("*")):
        rel = path.relative_to(ROOT)
        if (any(part in SKIP_DIRS or part.endswith(".egg-info") for part in rel.parts) or not path.is_file()
                or path == SELF):
            continue
        yield rel


@lru_cache(maxsize=None)
def _text(rel: Path) -> str:
    try:
        return (ROOT / rel).read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError):
        return ""


def _history_scope():
    """docs/ (with docs/bench/), config/, README.md and the code: every text file but the changelog."""
    for rel in _files():
        if rel.name == "CHANGELOG.md" or rel.suffix not in TEXT_SUFFIXES:
            continue
        if rel.parts[0] in ("docs", "config", "data") or rel.name == "README.md" or rel.suffix in CODE_SUFFIXES:
            yield rel


def _history_hits(rel: Path) -> list[str]:
    """The lines of one file that name a tracker number or a work-history label (a cheap keyword pass first)."""
    text = _text(rel)
    hits = [f"{rel}: file name"] if HISTORY.search(rel.name.replace("_", " ")) else []
    seen = set()
    for m in KEYWORD.finditer(text):
        start = text.rfind("\n", 0, m.start()) + 1
        if start in seen:
            continue
        seen.add(start)
        end = text.find("\n", m.end())
        line = text[start:None if end < 0 else end]
        if HISTORY.search(line):
            hits.append(f"{rel}:{text.count(chr(10), 0, start) + 1}: {line.strip()[:160]}")
    return hits


def test_no_tracker_numbers_or_work_history_labels():
    hits = [hit for rel in _history_scope() for hit in _history_hits(rel)]
    assert hits == [], f"{len(hits)} tracker / work-history references:\n" + "\n".join(hits[:80])


# ---------------------------------------------------------------------------------------------- references

TOP = {p.name for p in ROOT.iterdir() if not p.name.endswith(".egg-info")} - SKIP_DIRS
PACKAGES = sorted(p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file())
LINK = re.compile(r"\[[^\]\n]*\]\(([^)\s]+)\)")
REPO_PATH = re.compile(r"(?<![\w./<>{$%%*-])((?:%s)/(?:[\w.*-]+/)*(?:[\w.*-]*\.[A-Za-z0-9]+)?)(?![\w/<>{(-])"
                       % "|".join(map(re.escape, sorted(TOP))))
NOTE_FILE = re.compile(r"(?<![\w/.-])(\.\./[\w./-]*\w|[A-Z]{2,}(?:-[A-Z]{2,})+\b|[A-Z][A-Z_]+\.md\b)")
BARE_MODULE = re.compile(r"(?<![\w./<>{$%*-])([A-Za-z_]\w*\.py)\b")
DOTTED = re.compile(r"(?<![\w./-])((?:%s)(?:\.\w+)+)" % "|".join(map(re.escape, PACKAGES)))
SECTION = re.compile(r"([\w./-]+\.md)`?,?\s+(?:section\s+)?[\"“]([^\"”\n]{3,80})[\"”]")
SECTION_NUMBER = re.compile(r"([\w./-]+\.md)`?,?\s+section\s+(\d+)\b")
FILE_SUFFIXES = {"yaml", "py", "md", "xml", "json", "jsonl", "txt", "csv", "png", "c", "msg", "srv", "action"}
DOCSTRING = re.compile(r'("""|\'\'\')(.*?)\1', re.DOTALL)


def _doc_files():
    """The documents (docs/, README.md), config/ and the code whose paths and module names must resolve."""
    for rel in _files():
        if rel.suffix == ".md" and (rel.parts[0] == "docs" or rel == Path("README.md")):
            yield rel, "doc"
        elif rel.parts[0] == "config" and rel.suffix in (".yaml", ".xml"):
            yield rel, "config"
        elif rel.suffix == ".py" or rel.suffix in (".msg", ".srv", ".action", ".c", ".h", ".cfg", ".toml"):
            yield rel, "code"


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


@lru_cache(maxsize=None)
def _headings(rel: Path, lead_ins: bool = True) -> tuple[str, ...]:
    """A document's headings, and (lead_ins) the bold lead-ins of its paragraphs and list items (`**Camera
    images.**`), which a citation by name may name as well."""
    text = _text(rel)
    headings = tuple(m.group(1).strip() for m in re.finditer(r"^#{1,6}\s+(.+)$", text, re.MULTILINE))
    if not lead_ins:
        return headings
    return headings + tuple(m.group(1) for m in re.finditer(r"^(?:[-*] )?\*\*(.+?)\*\*", text, re.MULTILINE))


@lru_cache(maxsize=None)
def _file_names() -> frozenset[str]:
    """The names of the checkout's files: a bare `module.py` in the prose names one of them."""
    return frozenset(rel.name for rel in _files())


def _path_exists(name: str) -> bool:
    """A path in the checkout; `*` and a placeholder `XX` / `NN` (a numbered family of files) as globs."""
    name = re.sub(r"XX+|NN+", "*", name.rstrip("/").rstrip("."))
    return any(ROOT.glob(name)) if "*" in name else (ROOT / name).exists()


def _commentary(rel: Path) -> tuple[str, list[int]]:
    """What a file says in prose and the line number of each of its lines. A Python file's comments and
    triple-quoted strings (docstrings) only: code and its ordinary strings (test fixtures, formats) left out."""
    text = _text(rel)
    if rel.suffix != ".py":
        return text, list(range(1, text.count("\n") + 2))
    lines = text.split("\n")
    keep: dict[int, str] = {}
    for i, line in enumerate(lines):
        hash_at = line.find("#")
        if hash_at >= 0 and line[:hash_at].count('"') % 2 == 0 and line[:hash_at].count("'") % 2 == 0:
            keep[i] = line[hash_at:]
    for m in DOCSTRING.finditer(text):
        first = text.count("\n", 0, m.start())
        for j, piece in enumerate(m.group(0).split("\n")):
            keep[first + j] = piece
    numbers = sorted(keep)
    return "\n".join(keep[i] for i in numbers), [i + 1 for i in numbers]


def _document(doc: str, rel: Path) -> Path:
    """A cited document: relative to the citing file, to the checkout, or to docs/."""
    for base in (ROOT / rel.parent, ROOT, ROOT / "docs"):
        if (base / doc).is_file():
            return (base / doc).resolve()
    return ROOT / doc


def _module_defines(parts: list[str]) -> bool:
    """`a.b.c.name`: walk packages and modules as far as they go; the first other part is named in that module."""
    path = ROOT
    for i, part in enumerate(parts):
        if (path / part).is_dir():
            path = path / part
        elif (path / f"{part}.py").is_file():
            path = path / f"{part}.py"
        else:
            source = path / "__init__.py" if path.is_dir() else path
            rest = parts[i]
            return source.is_file() and re.search(rf"\b{re.escape(rest)}\b", source.read_text()) is not None
        if path.suffix == ".py" and i == len(parts) - 1:
            return True
    return True


def _broken_in(rel: Path, kind: str) -> list[str]:
    """The references of one file that do not resolve, with their line numbers."""
    text, numbers = _commentary(rel)
    broken = []

    def report(m: re.Match, what: str) -> None:
        broken.append(f"{rel}:{numbers[text.count(chr(10), 0, m.start())]}: {what}")

    if kind == "doc":
        for m in LINK.finditer(text):
            target = m.group(1)
            if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            dest = (ROOT / rel.parent / file).resolve() if file else ROOT / rel
            if not dest.exists():
                report(m, f"link {target}")
            elif anchor and dest.suffix == ".md" and anchor not in {
                    _slug(h) for h in _headings(dest.relative_to(ROOT), lead_ins=False)}:
                report(m, f"anchor {target}")
    for m in REPO_PATH.finditer(text):
        path = m.group(1)
        if not _path_exists(path):
            report(m, f"path {path}")
    for m in NOTE_FILE.finditer(text):  # `../x` out of its folder, a notes file (`STACK-NOTES`, `DESIGN.md`)
        name = m.group(1)
        dest = (ROOT / rel.parent / name).resolve() if name.startswith("../") else None
        if dest is not None and (not dest.is_relative_to(ROOT) or not dest.exists()):
            report(m, f"outside the repository: {name}")
        elif dest is None and name not in _file_names():
            report(m, f"no such document: {name}")
    for m in BARE_MODULE.finditer(text) if ".py" in text else ():
        if m.group(1) not in _file_names():
            report(m, f"module file {m.group(1)}")
    for m in DOTTED.finditer(text):
        parts = m.group(1).rstrip(".").split(".")
        if parts[-1] not in FILE_SUFFIXES and not _module_defines(parts):
            report(m, f"module path {m.group(1)}")
    if ".md" not in text:
        return broken
    for m in SECTION.finditer(text):
        doc, section = m.groups()
        target = _document(doc, rel)
        if not target.exists():
            report(m, f"document {doc}")
        elif not any(section.lower() in h.lower() for h in _headings(target.relative_to(ROOT))):
            report(m, f'section "{section}" of {doc}')
    for m in SECTION_NUMBER.finditer(text):
        doc, number = m.groups()
        target = _document(doc, rel)
        if not target.exists() or not any(h.startswith(f"{number}. ") for h in _headings(target.relative_to(ROOT))):
            report(m, f"section {number} of {doc}")
    return broken


def test_every_reference_resolves_inside_the_repository():
    broken = []
    for rel, kind in _doc_files():
        broken += _broken_in(rel, kind)
    assert broken == [], f"{len(broken)} unresolved references:\n" + "\n".join(broken[:120])


def test_the_checks_catch_what_they_are_for():
    """The patterns themselves: each kind of defect is found, and what is allowed passes."""
    for bad in ("(issue-14; docs/x.md)", "Issue #3", "issues\t13", "the final main of stop 32", "stop-33",
                "demo_stop33.txt", "round 2", "after this stop"):
        assert HISTORY.search(bad.replace("_", " ")), bad
    for good in ("rclpy#1452", "the arm stops 50 ms after", "20-round shutdown loops", "in/stop", "issues"):
        assert not HISTORY.search(good), good
    assert not _path_exists("docs/no_such_doc.md") and _path_exists("config/scenarios/*.yaml")
    assert [m.group(1) for m in NOTE_FILE.finditer("see STACK-NOTES and `../shared/DESIGN.md`; H-eG, RRT-Connect")] == [
        "STACK-NOTES", "../shared/DESIGN.md"]
    assert SECTION.findall('(docs/reliability.md, "Dead planner")') == [("docs/reliability.md", "Dead planner")]
    assert SECTION_NUMBER.findall("(docs/reliability.md, section 6)") == [("docs/reliability.md", "6")]
    assert _slug("Exact sequence from blockers (`astar.solve`)") == "exact-sequence-from-blockers-astarsolve"
    assert not _module_defines("qtree_task_planner.no_such_module.Thing".split("."))
    assert _module_defines("qtree_task_planner.learning.params.TrainingParams".split("."))
