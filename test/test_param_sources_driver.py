"""One source for every parameter of the simulated driver and of the settings it shares with the motion planner: the
YAML under config/ (as qtree_task_planner.learning.params.TrainingParams does). Each parameter dataclass loads from
its file; every field has exactly one key there and every key one field; no field carries a default of its own; and
no other dataclass of jaco2_sim_driver or relocation_common keeps a second value of a key (a default that drifts:
the driver's old `Rates` said state_on_command False while the file said true)."""
import dataclasses
import importlib
import pkgutil

import pytest
import yaml

from relocation_common.paths import config_file

# (module, class, config file, section): the parameter dataclasses and the file each one is read from
SOURCES = [("jaco2_sim_driver.params", "DriverParams", "jaco2_sim_driver.yaml", "jaco2_sim_driver"),
           ("relocation_common.arm_interface", "ArmInterface", "arm_interface.yaml", "/**")]
# fields of other dataclasses that hold a key's value under another name (CameraSpec is built from the camera keys)
ALIASES = {"fovy_deg": "camera_fovy", "width": "camera_width", "height": "camera_height",
           "joint_states": "joint_state_rate", "tf": "tf_rate", "objects": "objects_rate"}


def _section_keys(name: str, section: str) -> list[str]:
    """The keys of `section: ros__parameters:` as written, duplicates included (yaml.safe_load keeps the last)."""
    root = yaml.compose(config_file(name).read_text())
    node = next(v for k, v in root.value if k.value == section)
    params = next(v for k, v in node.value if k.value == "ros__parameters")
    return [k.value for k, _ in params.value]


def _no_default(f: dataclasses.Field) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


@pytest.mark.parametrize("module,cls,name,section", SOURCES)
def test_each_parameter_dataclass_loads_from_its_yaml_with_one_key_per_field(module, cls, name, section):
    klass = getattr(importlib.import_module(module), cls)
    keys = _section_keys(name, section)
    fields = [f.name for f in dataclasses.fields(klass)]
    assert sorted(k for k in set(keys) if keys.count(k) > 1) == [], f"keys given twice in config/{name}"
    assert sorted(set(fields) - set(keys)) == [], f"{cls} fields without a key in config/{name}"
    assert sorted(set(keys) - set(fields)) == [], f"config/{name} keys without a field of {cls}"
    assert [f.name for f in dataclasses.fields(klass) if not _no_default(f)] == [], f"{cls} fields with a default"
    loaded = klass.load()
    values = yaml.safe_load(config_file(name).read_text())[section]["ros__parameters"]
    for k, v in values.items():  # the file's values, as the loader typed them
        assert getattr(loaded, k) == (v.rstrip("/") if k == "driver_prefix" else v), k


def test_no_key_is_in_two_files():
    owners: dict[str, list[str]] = {}
    for _, _, name, section in SOURCES:
        for k in _section_keys(name, section):
            owners.setdefault(k, []).append(name)
    assert {k: v for k, v in owners.items() if len(v) > 1} == {}


def _dataclasses(package: str):
    pkg = importlib.import_module(package)
    for info in pkgutil.iter_modules(pkg.__path__, f"{package}."):
        module = importlib.import_module(info.name)
        for obj in vars(module).values():
            if dataclasses.is_dataclass(obj) and isinstance(obj, type) and obj.__module__ == module.__name__:
                yield obj


def test_no_other_dataclass_keeps_a_second_value_of_a_key():
    """A field named as a key of the driver's or the arm interface's file (or one of ALIASES) has no default. (A
    missing file is the first test's failure; here the keys of the files there are.)"""
    keys = {k for _, _, name, section in SOURCES if config_file(name).is_file() for k in _section_keys(name, section)}
    seconds = sorted(f"{c.__module__}.{c.__name__}.{f.name}" for package in ("jaco2_sim_driver", "relocation_common")
                     for c in _dataclasses(package) for f in dataclasses.fields(c)
                     if ALIASES.get(f.name, f.name) in keys and not _no_default(f))
    assert seconds == []
