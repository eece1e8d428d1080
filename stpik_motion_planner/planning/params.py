"""The motion planner's parameters (docs/motion_planner.md): `PlannerParams`, with STPIK's (`StpikParams`, the
stpik.* keys) inside, validated once. Their values live in ONE place, config/motion_planner.yaml (ROS params-file
form, the motion_planner node's section); the dataclasses carry no second set: `PlannerParams.load()` gives the
shipped values, `load(path)` a file's values over them (as a --params-file overrides the node's).
"""
from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, fields
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from relocation_common.config import node_section
from relocation_common.paths import config_file
from stpik_motion_planner.planning.stpik import StpikParams

NODE_NAME = "motion_planner"
FILE = "motion_planner.yaml"
PUSH = "push."  # the push's keys (PushParams)
WHOLE_NUMBERS = ("max_attempts", "n_yaws", "wide_yaws", "seed", "rrt_max_checks", "simplify_checks")
SWITCHES = ("direct_first", "seed_per_query", "screen_at_clearance", "certify_relocation")


def node_parameters(path: str | Path | None = None) -> dict[str, Any]:
    """The motion_planner node's section of config/motion_planner.yaml, with the keys of the file at `path` (if
    any) over it. ParameterError (a ValueError) naming the file on malformed YAML or a wrong layout."""
    values = node_section(config_file(FILE), NODE_NAME)
    if path is not None:
        values.update(node_section(path, NODE_NAME))
    return values


@dataclass
class PushParams:
    """The push of a cylinder out of another object's grasp lanes (planning/push/; the push.* keys)."""

    contact_height: float  # fraction of the pushed object's height at which the closed finger tips touch it
    distances: tuple[float, ...]  # m the object is pushed, the candidates tried least first
    directions: tuple[float, ...]  # rad from straight back (+x), turned away from the object the push clears for
    sweep_margin: float  # m the pushed object's swept footprint keeps from every other object and the shelf's panels
    contact_gap: float  # m between the finger tips and the object at the contact pose (the push starts there)
    speed: float  # m/s of the tool along the push (quasi-static: the object stops when the hand does)
    lying_distances: tuple[float, ...]  # m a lying cylinder is pushed, the candidates tried least first
    slide: bool  # a lying cylinder slid along its axis (the tips against its end cap) may be planned
    roll: bool  # a lying cylinder rolled across its axis (the tips against its side) may be planned
    hand_turns: tuple[float, ...]  # rad the hand of a slide is turned from the push towards straight in, in order

    def __post_init__(self) -> None:
        """Every setting checked once, with its name in the error (ValueError)."""
        if not (isinstance(self.contact_height, (int, float)) and 0.0 < self.contact_height < 1.0):
            raise ValueError(f"motion planner parameter push.contact_height must be in (0, 1), got "
                             f"{self.contact_height!r}")
        for k in ("sweep_margin", "contact_gap", "speed"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0 \
                    or (v == 0 and k == "speed"):
                raise ValueError(f"motion planner parameter push.{k} must be a finite number "
                                 f"{'> 0' if k == 'speed' else '>= 0'}, got {v!r}")
        for k in ("slide", "roll"):
            if not isinstance(getattr(self, k), bool):
                raise ValueError(f"motion planner parameter push.{k} must be true or false, got {getattr(self, k)!r}")
        for k in ("distances", "lying_distances"):
            d = np.asarray(getattr(self, k), float)
            if d.ndim != 1 or not len(d) or not np.all(np.isfinite(d) & (d > 0)) or np.any(np.diff(d) <= 0):
                raise ValueError(f"motion planner parameter push.{k} must be positive metres, increasing, got "
                                 f"{getattr(self, k)!r}")
        t = np.asarray(self.hand_turns, float)
        if t.ndim != 1 or not len(t) or not np.all(np.isfinite(t) & (t >= 0) & (t <= 1.0)):
            raise ValueError(f"motion planner parameter push.hand_turns must be angles in [0, 1] rad, got "
                             f"{self.hand_turns!r}")
        a = np.asarray(self.directions, float)
        if a.ndim != 1 or not len(a) or not np.all(np.isfinite(a) & (a >= 0) & (a < math.pi / 2)):
            raise ValueError(f"motion planner parameter push.directions must be angles in [0, pi/2) rad, got "
                             f"{self.directions!r}")


@dataclass
class PlannerParams:
    """The motion planner's settings (config/motion_planner.yaml, docs/motion_planner.md), validated once."""

    seed: int  # OMPL's process-wide RNG, seeded once per process
    timeout: float  # s: wall-clock safety net per feasibility query (the service may pass its own)
    rrt_max_checks: int  # validity checks per RRT-Connect attempt
    max_attempts: int  # sampled paths per query before answering g_U
    n_yaws: int  # approach yaws of the first tier (grasp.yaw_tiers)
    max_yaw: float  # rad
    wide_yaws: int  # the second tier, tried when the first found nothing; 0: none
    wide_max_yaw: float  # rad
    pre_grasp_distance: float  # m back along the approach
    hand_margin: float  # m: inflation of the hand proxy in the Cartesian planner
    resolution: float  # m: motion checking resolution of the Cartesian planner
    joint_resolution: float  # rad: of the joint-space planner
    simplify_checks: int  # validity checks of OMPL path simplification (0: none)
    lift: float  # m, after the grasp (at least carried_clearance + stpik.act: grasp.carry_heights)
    drop: float  # m, bottle base above the bottom shelf at release (at most half the room: carry_heights)
    carried_clearance: float  # m, the carried bottle (real size) to boards and bottles
    carry_ramp: float  # s to full speed and to a stop at each waypoint of the carry and retreat (0: none)
    carry_accel: float  # rad/s^2, joint accelerations while a bottle is held (0: no limit)
    stage_distance: float  # m, staging pose in front of the slot (at most x_front - 0.07: grasp.place_poses)
    carry_timeout: float  # s: wall-clock safety net of plan_pick / plan_carry / plan_home
    direct_first: bool  # try home -> front of shelf -> pre-grasp before sampling with RRT-Connect
    seed_per_query: bool  # every OMPL solve seeded from the question (question_rng), not process history
    screen_at_clearance: bool  # the grasp screen's hand proxy inflated by at least stpik.clearance
    certify_relocation: bool  # every feasible answer certified (eager); false: the pick, certified when asked (lazy)
    reuse_distance: float  # m: objects farther from a pick's motion entered none of its checks (its `near` set)
    flat_tilt: float  # rad: a perceived cylinder's axis this close to horizontal lies flat (scene_update.laid_flat)
    workspace_lo: tuple[float, ...]  # (x, y, z, yaw) box of the Cartesian planner
    workspace_hi: tuple[float, ...]
    stpik: StpikParams
    push: PushParams

    def __post_init__(self) -> None:
        """Every setting checked once, with its name in the error (ValueError)."""
        positive = ("timeout", "pre_grasp_distance", "resolution", "joint_resolution",
                    "stage_distance", "carry_timeout", "carried_clearance", "flat_tilt")
        non_negative = ("max_yaw", "wide_max_yaw", "hand_margin", "lift", "drop", "carry_ramp", "carry_accel",
                        "reuse_distance")
        for k in positive + non_negative:
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0 or (v == 0 and k in positive):
                raise ValueError(f"motion planner parameter {k} must be a finite number "
                                 f"{'> 0' if k in positive else '>= 0'}, got {v!r}")
        for k in WHOLE_NUMBERS:
            v, least = getattr(self, k), {"seed": None, "simplify_checks": 0, "wide_yaws": 0}.get(k, 1)
            if isinstance(v, bool) or not isinstance(v, int) or (least is not None and v < least):
                raise ValueError(f"motion planner parameter {k} must be an integer"
                                 f"{'' if least is None else f' >= {least}'}, got {v!r}")
        for k in SWITCHES:
            if not isinstance(getattr(self, k), bool):
                raise ValueError(f"motion planner parameter {k} must be true or false, got {getattr(self, k)!r}")
        band = self.checked_distance()
        if self.reuse_distance < band:
            raise ValueError(f"motion planner parameter reuse_distance must be at least {band:g} m (the widest band "
                             f"a check of a pick looks at: hand_margin, stpik.clearance + stpik.buffer), got "
                             f"{self.reuse_distance!r}")
        lo, hi = (np.asarray(getattr(self, k), float) for k in ("workspace_lo", "workspace_hi"))
        if lo.shape != (4,) or hi.shape != (4,) or not np.all(np.isfinite(lo) & np.isfinite(hi) & (lo < hi)):
            raise ValueError(f"motion planner parameters workspace_lo < workspace_hi must be 4 finite numbers each "
                             f"(x, y, z, yaw), got {self.workspace_lo!r}, {self.workspace_hi!r}")

    def checked_distance(self) -> float:
        """The widest distance at which an object enters a check of a pick (m): the hand proxy's inflation
        (hand_margin, or stpik.clearance with screen_at_clearance) and STPIK's candidate band (clearance + buffer)."""
        s = self.stpik
        return max(self.hand_margin, s.clearance, s.clearance + s.buffer)

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The flat parameter names (ROS parameters): the planner's own and stpik.* for StpikParams."""
        return tuple(f.name for f in fields(cls) if f.name not in ("stpik", "push")) + tuple(
            f"stpik.{f.name}" for f in fields(StpikParams)) + tuple(f"{PUSH}{f.name}" for f in fields(PushParams))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> PlannerParams:
        """From a flat mapping (ROS parameters) with every key of `keys()`; stpik.* keys go to StpikParams. Unknown
        or missing keys are an error (ValueError)."""
        own = {f.name for f in fields(cls)} - {"stpik", "push"}
        sp = {f.name for f in fields(StpikParams)}
        kw: dict[str, Any] = {}
        skw: dict[str, Any] = {}
        pkw: dict[str, Any] = {}
        for k, v in data.items():
            if k.startswith("stpik.") and k[6:] in sp:
                skw[k[6:]] = v
            elif k.startswith(PUSH) and k[len(PUSH):] in {f.name for f in fields(PushParams)}:
                pkw[k[len(PUSH):]] = tuple(float(x) for x in v) if isinstance(v, Sequence) and not isinstance(
                    v, str) else v
            elif k in own:
                # a list in YAML, a tuple or array('d') from ROS: one form, so the question's seed is the same
                kw[k] = tuple(float(x) for x in v) if isinstance(v, Sequence) and not isinstance(v, str) else v
            else:
                raise ValueError(f"motion planner parameter {k!r} is unknown; known: {sorted(own)} and stpik.*")
        required = [f"stpik.{f.name}" for f in fields(StpikParams)  # the joint speed limits: the robot's if not given
                    if f.default is MISSING and f.default_factory is MISSING]
        missing = [k for k in cls.keys() if k not in kw and k in own or k in required and k[6:] not in skw
                   or k.startswith(PUSH) and k[len(PUSH):] not in pkw]
        if missing:
            raise ValueError(f"motion planner parameter(s) missing: {', '.join(missing)}")
        for k in WHOLE_NUMBERS:  # whole numbers only
            if isinstance(kw.get(k), float) and kw[k].is_integer():
                kw[k] = int(kw[k])
        return cls(**kw, stpik=StpikParams(**skw), push=PushParams(**pkw))

    @classmethod
    def load(cls, path: str | Path | None = None) -> PlannerParams:
        """The planner's keys of config/motion_planner.yaml, with those of the ROS params file at `path` (if any)
        over them. The keys the shipped file gives the motion_planner node for itself are skipped; any other unknown
        key is an error. ValueError naming the file on malformed YAML, a wrong layout or a bad value."""
        node_keys = set(node_parameters()) - set(cls.keys())
        section = node_parameters(path)
        try:
            return cls.from_mapping({k: v for k, v in section.items() if k not in node_keys})
        except (TypeError, ValueError) as e:
            raise ValueError(f"{path if path is not None else config_file(FILE)}: {e}") from None
