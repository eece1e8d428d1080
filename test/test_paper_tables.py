"""Complete-tree sizes, the paper's Tables 1-4 (data/paper/) and the side-by-side report sections."""
from __future__ import annotations

import itertools

import pytest

from qtree_task_planner.oracles import BlockingOracle
from relocation_app.evaluation import paper
from relocation_app.evaluation.__main__ import SCEN_DIR, planner_params
from relocation_app.evaluation.feasibility_cache import FeasibilityTable, open_table
from relocation_app.evaluation.reports import claims, paper_report
from relocation_app.evaluation.scenes import complete_tree
from relocation_common.feasibility import Label
from relocation_common.paths import data_dir
from relocation_common.scenario import load_scenario


def _naive(obstacles, target, label_of):
    """Edges and target leaves by walking every sequence (no memo): the definition, for small scenes."""
    edges = leaves = 0
    for k in range(len(obstacles) + 1):
        for seq in itertools.permutations(obstacles, k):
            if all(label_of(o, frozenset(seq[:i])) == Label.OBSTACLE for i, o in enumerate(seq)):
                edges += len(obstacles) + 1 - k
                leaves += label_of(target, frozenset(seq)) == Label.TARGET
    return edges, leaves


def test_complete_tree_matches_the_definition_on_a_blocking_scene():
    sc = load_scenario(SCEN_DIR / "blocking_5.yaml")
    oracle = BlockingOracle(sc)
    size = complete_tree.of_oracle(oracle, sc)

    def label_of(o, s):
        return oracle.feasibility(o, s).label

    assert (size.edges, size.target_leaves) == _naive(sc.obstacle_ids, sc.target_id, label_of)
    assert size.optimal_leaves == 1  # blocking_5: unique optimum o1 o4 T (its header)
    assert size.optimal_weight == pytest.approx(sc.weights["o1"] + sc.weights["o4"])


def test_complete_tree_of_scenario1_is_lrnd_mpq():
    """scenario1_5's LRND MP_q is 442 at alpha < 1 (LRND completes the tree; docs/evaluation.md quotes 442)."""
    sc = load_scenario(SCEN_DIR / "scenario1_5.yaml")
    table, _ = open_table(sc, planner_params(), data_dir() / "feasibility")
    size = complete_tree.of_table(table, sc)
    assert size.edges == 442
    partial = FeasibilityTable("k")
    partial.put("T", frozenset(), Label.UNFEASIBLE)
    with pytest.raises(ValueError, match="no answer"):
        complete_tree.of_table(partial, sc)


def test_paper_tables_read_with_their_marks():
    assert sum(len(paper.cells(k)) for k in (1, 2, 3)) == 162
    assert paper.cells(1)[("LRND_b", 0.3, 0.9)] == {"E_ss": 511, "MP_q": 84, "E_1st": 50, "E_1st_pen": 50}
    assert paper.cells(2)[("LRND_b", 1.0, 0.9)]["E_ss"] is None  # the row absent from the text
    assert paper.mark(1, 1, 1.0, 0.5, "H-eG_b", "E_1st") == "?"
    assert paper.mark(2, 2, 0.3, 0.9, "LRND_b", "MP_q") == "!"
    assert paper.mark(1, 1, 0.3, 0.9, "LRND_b", "MP_q") == ""
    t4 = paper.table4()
    assert sorted(t4) == list(range(1, 11)) and all(len(v) == 6 for v in t4.values())
    assert t4[10]["H-eG_d"]["E_1st"] is None and paper.mark(4, 9, None, None, "H-eG_d", "E_ss") == "?"


def test_findings_on_the_papers_own_numbers():
    idx = paper.index()
    main = [f"paper scenario {k}" for k in (1, 2, 3)]
    found = {c: v for c, v, _ in claims.check(idx, main, main[1:], [f"paper case {c}" for c in range(1, 11)])}
    assert found["H-eG_b needs the fewest motion-planner queries MP_q"] == "reproduced"
    assert found["H-eG_d has the best E_ss in the complex scenes"] == "reproduced"
    assert found["Higher alpha and lower gamma are better (mean E_ss and E_1st over algorithms)"] == "partly (4/6)"


def test_side_by_side_cells_and_tree_table():
    ours = {k: dict(v) for k, v in paper.cells(1).items()}
    ours[("LRND_b", 0.3, 0.9)]["E_ss"] = 1022.0
    text = paper_report.side_by_side(ours, 1)
    assert "| LRND_b | 511 / 1022 (2) |" in text
    assert "146? / 146 (1)" in text  # uncertain paper cell marked
    assert "E_ss ours/paper median 1" in paper_report.ratio_summary(ours, 1)
    row = paper_report.tree_table([("x", 2, complete_tree.TreeSize(1244, 20, 300, 1, 1.0))])
    assert "622 / 1244 (2)" in row and "20 / 20" in row


def test_closing_note_names_sizes_and_both_verdicts():
    sc = load_scenario(SCEN_DIR / "scenario1_5.yaml")
    table, _ = open_table(sc, planner_params(), data_dir() / "feasibility")
    found = [("the paper's numbers", [("claim A", "reproduced", "")]), ("ours", [])]
    note = paper_report.closing_note({"scenario1_5": (sc, table, None)}, [], ["scenario1_5"], found)
    assert "scenario1_5 442 edges / 203 target leaves / 1 optimal (paper 84 / 10 / 1)" in note
    assert "- claim A: the paper's numbers **reproduced**; ours **not checked**." in note
