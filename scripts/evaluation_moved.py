"""What moved between two versions of docs/evaluation.md (the generated report, `./run evaluate`): per "beside the
paper" table (Tables 1-4), how many of our cells changed and the "Ratios" line before and after; the summary's
findings, the scenes' and complete trees' rows that changed. Prints Markdown to paste into docs/bench/.

    .venv/bin/python scripts/evaluation_moved.py --old <commit> [--new <commit or path>]   # default new: the file
"""
from __future__ import annotations

import argparse
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = "docs/evaluation.md"
OURS = re.compile(r"/ ([^/()|]+?) \(")  # "paper / ours (ratio)": ours


def text(ref: str) -> str:
    """The report at a commit, or a file's text when `ref` is a path."""
    if Path(ref).is_file():
        return Path(ref).read_text()
    return subprocess.run(["git", "show", f"{ref}:{DOC}"], cwd=ROOT, capture_output=True, text=True, check=True).stdout


def sections(md: str) -> dict[str, list[str]]:
    """'## ' heading -> its lines."""
    out: dict[str, list[str]] = {}
    cur = ""
    for line in md.splitlines():
        if line.startswith("## "):
            cur = line[3:].strip()
        out.setdefault(cur, []).append(line)
    return out


def ours_cells(lines: list[str]) -> list[str]:
    """Our value of every 'paper / ours (ratio)' cell of a section, in order."""
    return [m.group(1).strip() for ln in lines if ln.startswith("| ") for m in OURS.finditer(ln)]


def rows(lines: list[str]) -> dict[str, str]:
    """Table rows of a section by their first cell."""
    return {ln.split("|")[1].strip(): ln for ln in lines if ln.startswith("| ") and not ln.startswith("|---")}


def moved(old: str, new: str) -> str:
    """The Markdown summary of what changed (the module docstring)."""
    a, b = sections(old), sections(new)
    md = ["| table | our cells changed | Ratios before | Ratios after |", "|---|---:|---|---|"]
    for name in b:
        if "beside the paper" not in name or name not in a:
            continue
        oa, ob = ours_cells(a[name]), ours_cells(b[name])
        n = sum(x != y for x, y in zip(oa, ob)) + abs(len(oa) - len(ob))
        ra = next((ln[len("Ratios: "):] for ln in a[name] if ln.startswith("Ratios:")), "-")
        rb = next((ln[len("Ratios: "):] for ln in b[name] if ln.startswith("Ratios:")), "-")
        md.append(f"| {name} | {n} of {len(ob)} | {ra} | {rb if rb != ra else 'same'} |")
    for name in ("Summary", "Scenes (feasibility from the real planner)",
                 "Complete trees: the paper's scenes against ours"):
        ra, rb = rows(a.get(name, [])), rows(b.get(name, []))
        changed = [(k, ra.get(k), v) for k, v in rb.items() if ra.get(k) != v]
        before = {ln.split(":")[0]: ln for ln in a.get(name, []) if ln.startswith("- ")}  # a finding by its claim
        changed += [(ln, before.get(ln.split(":")[0]), ln) for ln in b.get(name, [])
                    if ln.startswith("- ") and ln not in a.get(name, [])]
        md.append(f"\n**{name}**: {len(changed)} row(s) changed" + (":" if changed else ""))
        for _, before, after in changed:
            md.append(f"- before: {before or '(none)'}\n  after:  {after}")
    return "\n".join(md)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="commit (or path) of the earlier report")
    ap.add_argument("--new", default=str(ROOT / DOC), help="commit or path of the later report (default: the file)")
    a = ap.parse_args()
    print(moved(text(a.old), text(a.new)))


if __name__ == "__main__":
    main()
