"""Fig. 3 (docs/evaluation.md): the Q-Tree is drawn by Graphviz's dot from the text QTree.to_dot writes, and a
machine without Graphviz gets one line saying to install it."""
import struct
from pathlib import Path

import pytest

from relocation_app.evaluation.reports import figures

DOT = Path(__file__).resolve().parent.parent / "docs" / "figures" / "tree_scenario1_5.dot"


def _png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    return struct.unpack(">II", head[16:24])


def test_fig3_is_drawn_by_dot_from_the_tree_text(tmp_path):
    png = figures.tree_figure(DOT, tmp_path / "tree.png", "Fig. 3: a title")
    width, height = _png_size(png)
    assert height > width > 500  # left to right: the depth across, the 38 nodes and their leaves down


def test_without_graphviz_one_line_says_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setattr(figures.shutil, "which", lambda name: None)
    with pytest.raises(SystemExit) as e:
        figures.tree_figure(DOT, tmp_path / "tree.png", "Fig. 3")
    message = str(e.value.code)
    assert "install graphviz" in message and "\n" not in message
    assert not (tmp_path / "tree.png").exists()
