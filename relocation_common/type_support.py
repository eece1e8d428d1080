"""The project's interfaces checked at start: the Python classes of qtree_relocation_msgs and the C type support
libraries the process loaded for them must come from one build of msg_defs/.

A Python package generated from a newer PlanFeasibility than the C libraries found first on LD_LIBRARY_PATH loses
the fields the libraries do not know, silently, on every message: a node then answers a feasible pick without its
near set (`near_known` false: no reuse across answers, the task planner asks several times the questions) and takes
a certify request for a plain pick (`certify` false). The ros_wheels_bootstrapper of the venv (its .pth) orders
LD_LIBRARY_PATH through a Python set, so with two builds on it which one a process loads changes from one start to
the next. `check_type_support` sends one message of every type, each field set away from its default, through
rclpy's serialization (the C libraries) and back, and raises InterfaceMismatch naming the fields lost.
"""
from __future__ import annotations

import importlib
import sys
from typing import Any

PACKAGE = "qtree_relocation_msgs"
_PARTS = {"msg": (), "srv": ("Request", "Response"), "action": ("Goal", "Result", "Feedback")}


class InterfaceMismatch(Exception):
    """The interface package's Python classes and its C libraries come from different builds."""


def interface_types(package: str = PACKAGE) -> list[type]:
    """Every message class of `package`: its messages, the requests and responses of its services, the goals,
    results and feedback of its actions."""
    out: list[type] = []
    for sub, parts in _PARTS.items():
        mod = importlib.import_module(f"{package}.{sub}")
        for name in sorted(n for n in dir(mod) if not n.startswith("_")):
            obj = getattr(mod, name)
            if isinstance(obj, type) and parts and all(hasattr(obj, p) for p in parts):
                out.extend(getattr(obj, p) for p in parts)
            elif isinstance(obj, type) and not parts and hasattr(obj, "get_fields_and_field_types"):
                out.append(obj)
    return out


def sample(cls: Any, package: str = PACKAGE) -> Any:
    """An instance of message class `cls` with every field away from its default (nested messages of `package`
    likewise, one element in each sequence; fixed-size arrays and other packages' messages left as they are)."""
    from rosidl_parser.definition import AbstractSequence, NamespacedType

    msg = cls()
    for (name, _), slot in zip(cls.get_fields_and_field_types().items(), cls.SLOT_TYPES):
        value = getattr(msg, name)
        if isinstance(slot, AbstractSequence):
            t = slot.value_type
            if isinstance(t, NamespacedType):
                elem = getattr(importlib.import_module(".".join(t.namespaces)), t.name)
                value.append(sample(elem, package) if t.namespaces[0] == package else elem())
            elif hasattr(value, "typecode"):  # array.array of numbers
                value.append(0.5 if value.typecode in "fd" else 1)
            else:
                value.append(_scalar(t.typename if hasattr(t, "typename") else "string"))
        elif isinstance(slot, NamespacedType):
            value = sample(type(value), package) if slot.namespaces[0] == package else value
        elif isinstance(value, (bool, int, float, str, bytes)):
            value = _flip(value)
        setattr(msg, name, value)
    return msg


def _flip(value: bool | int | float | str | bytes) -> bool | int | float | str | bytes:
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value + 0.5
    return value + "x" if isinstance(value, str) else value + b"\x01"


def _scalar(typename: str) -> bool | int | float | str:
    if typename == "boolean":
        return True
    if typename in ("float", "double"):
        return 0.5
    return "x" if "string" in typename or typename == "char" else 1


def lost_fields(cls: Any, package: str = PACKAGE) -> list[str]:
    """The fields of `cls` that do not come back equal from a round trip through the C type support."""
    from rclpy.serialization import deserialize_message, serialize_message

    sent = sample(cls, package)
    back = deserialize_message(serialize_message(sent), cls)
    return [f for f in cls.get_fields_and_field_types()
            if repr(getattr(back, f, "<missing>")) != repr(getattr(sent, f))]


def check_type_support(package: str = PACKAGE) -> None:
    """InterfaceMismatch when a message of `package` loses a field in the C type support (the module docstring),
    naming the fields, where the Python package and the C libraries were loaded from, and what to do."""
    lost = {f"{cls.__module__.split('.')[1]}/{cls.__name__}": f for cls in interface_types(package)
            if (f := lost_fields(cls, package))}
    if not lost:
        return
    where = sys.modules[package].__file__ or package
    libs = sorted({line.split()[-1] for line in _maps() if f"lib{package}__" in line})
    fields = "; ".join(f"{t}: {' '.join(f)}" for t, f in lost.items())
    raise InterfaceMismatch(
        f"{package}: fields lost in the C type support ({fields})"
        f": the Python package ({where.rsplit('/', 1)[0]}) and the C libraries loaded "
        f"({', '.join(libs) or 'unknown'}) come from different builds of msg_defs/. Rebuild them together "
        "(bash scripts/setup_env.sh); a package installed elsewhere needs its own lib/ alone on LD_LIBRARY_PATH")


def _maps() -> list[str]:
    try:
        with open("/proc/self/maps") as f:
            return f.read().splitlines()
    except OSError:
        return []
