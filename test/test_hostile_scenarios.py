"""Hostile or broken scenario files (docs/reliability.md): one short ScenarioError naming the file and the key, never a
traceback, a hang or a runaway allocation. Old code: tracebacks (non-numbers in `defaults`, a mapping in a
`blocking:` list), NaN heights accepted (MuJoCo crashed in the driver), ids breaking the driver's MJCF, marker id
1e300 and dictionary NOPE accepted, a "billion laughs" growing memory ~20 MB/s, RecursionError on deep nesting,
a 50 MB file still parsing after 240 s."""
import subprocess
import sys
import time

import pytest
import yaml

from relocation_common.config import MAX_MESSAGE
from relocation_common.paths import default_scenario
from relocation_common.scenario import ScenarioError, load_scenario

BASE = default_scenario().read_text()
DATA = yaml.safe_load(BASE)


def variant(tmp_path, change) -> str:
    d = yaml.safe_load(BASE)
    change(d)
    f = tmp_path / "s.yaml"
    f.write_text(yaml.safe_dump(d))
    return str(f)


def set_first_object(key, value):
    return lambda d: d["objects"][0].__setitem__(key, value)


CASES = {
    "radius is a word": (lambda d: d.__setitem__("defaults", {"radius": "big"}), "radius must be a finite number"),
    "height is a list": (lambda d: d.__setitem__("defaults", {"height": [1, 2]}), "height must be a finite number"),
    "NaN height": (lambda d: d.__setitem__("defaults", {"height": float("nan")}), "height must be a finite number"),
    "markup in an id": (set_first_object("id", 'o1"<&'), "id must be a letter"),
    "marker id 1e300": (lambda d: d["marker"].__setitem__("id", 1e300), "marker: id must be an integer"),
    "dictionary NOPE": (lambda d: d["marker"].__setitem__("dictionary", "NOPE"), "dictionary must be one of"),
    "mapping in blocking": (lambda d: d.__setitem__("blocking", {"T": [{"a": 1}]}), "blocking[T]"),
}


@pytest.mark.parametrize("name", CASES)
def test_bad_values_get_one_short_error_naming_the_key(tmp_path, name):
    change, fragment = CASES[name]
    with pytest.raises(ScenarioError, match=fragment.replace("[", r"\[")) as e:
        load_scenario(variant(tmp_path, change))
    assert "\n" not in str(e.value) and len(str(e.value)) <= MAX_MESSAGE


def test_a_billion_laughs_is_refused_at_once(tmp_path):
    lines = ['a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    lines += [f"a{k}: &a{k} [" + ",".join([f"*a{k - 1}"] * 10) + "]" for k in range(1, 9)]
    f = tmp_path / "laughs.yaml"
    f.write_text("\n".join(lines) + "\nname: x\nobjects:\n- id: *a8\n")
    t0 = time.monotonic()
    with pytest.raises(ScenarioError, match="aliases"):
        load_scenario(f)
    assert time.monotonic() - t0 < 1.0


def test_deep_nesting_and_huge_files_are_refused(tmp_path):
    f = tmp_path / "deep.yaml"
    f.write_text("name: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ScenarioError, match="nested deeper"):
        load_scenario(f)
    f = tmp_path / "huge.yaml"
    f.write_text(BASE + "#" * (50 << 20) + "\n")
    t0 = time.monotonic()
    with pytest.raises(ScenarioError, match="too large"):
        load_scenario(f)
    assert time.monotonic() - t0 < 1.0


def test_the_cli_prints_one_line_and_exits_2(tmp_path):
    path = variant(tmp_path, CASES["radius is a word"][0])
    r = subprocess.run([sys.executable, "-m", "relocation_app.cli", "solve", "--scenario", path],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "radius" in r.stderr, r.stderr
