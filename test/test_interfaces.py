"""Interface packages built from msg_defs/ by scripts/setup_env.sh.

- kinova_msgs: the types this project uses, exactly as in Kinova's ROS 1 driver kinova-ros
  (github.com/Kinovarobotics/kinova-ros, folder kinova_msgs, branch noetic-devel): same names, field names, types
  and order. The definitions are written out below as they are there, not read from msg_defs/.
- tf2_msgs/msg/TFMessage exactly as in ROS 2 Jazzy's geometry2, checked by its RIHS01 type hash: the one a Jazzy
  node advertises for /tf (`ros2 topic info -v /tf`), found in public generated code and bag metadata.
- qtree_relocation_msgs still imports after the move to msg_defs/qtree_relocation_msgs/ (without its JointVelocity:
  kinova_msgs/JointVelocity replaced it); its ObjectState carries a primitive as moveit_msgs/CollisionObject does
  (shape_msgs/SolidPrimitive, full orientation, listed, the weight's note, colour, fit quality), and the installed
  type is the one msg_defs/ defines (a stale build fails).

The type hash is checked twice: in the type description installed beside the type
(share/<pkg>/<kind>/<Type>.json, key "type_hashes") and as advertised on the graph by a publisher of this process
(from the compiled type support).
"""
import json
import os
from pathlib import Path

import pytest

# Kinova's definitions (kinova-ros noetic-devel, kinova_msgs/), verbatim.
KINOVA_ROS = {
    "msg/JointVelocity": """\
float32 joint1
float32 joint2
float32 joint3
float32 joint4
float32 joint5
float32 joint6
float32 joint7
""",
    "msg/JointAngles": """\
float32 joint1
float32 joint2
float32 joint3
float32 joint4
float32 joint5
float32 joint6
float32 joint7
""",
    "msg/FingerPosition": """\
float32 finger1
float32 finger2
float32 finger3
""",
    "action/SetFingersPosition": """\
# Goal
FingerPosition fingers
---
# Result
FingerPosition fingers
---
# Feedback message
FingerPosition fingers
""",
    "action/ArmJointAngles": """\
# Goal
JointAngles angles
---
# Result
JointAngles angles
---
# Feedback
JointAngles angles
""",
    "srv/HomeArm": """\
---
string homearm_result
""",
    "srv/Start": """\
---
string start_result
""",
    "srv/Stop": """\
---
string stop_result
""",
}

# ROS 2 Jazzy geometry2, tf2_msgs/msg/TFMessage.msg, verbatim.
TF2_MSGS = {
    "msg/TFMessage": """\
geometry_msgs/TransformStamped[] transforms
""",
}

# qtree_relocation_msgs/msg/ObjectState: the fields the nodes exchange (relocation_common.ros_conversions).
OBJECT_STATE = """\
string id
string label
std_msgs/ColorRGBA color
float64 weight
string weight_note
bool is_target
bool listed
geometry_msgs/Pose pose
shape_msgs/SolidPrimitive shape
float64 fit_rms
bool conservative
"""

# RIHS01 hash of tf2_msgs/msg/TFMessage in ROS 2 Jazzy, as published: `ros2 topic info -v` output of a Jazzy
# system, Jazzy rosbag2 metadata (type_description_hash), and the EXPECTED_HASH constants of rosidl_generator_c
# code generated against Jazzy's tf2_msgs (whose hashes for TransformStamped, Header and Time are those of this
# venv's Jazzy wheels).
TF_MESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"

# No RIHS01 hashes of kinova_msgs are published (the public ROS 2 ports, RRL-ALeRT/kinova-ros2 and
# Syoris/kinova_ros2, target Humble, which has none). These were computed with Jazzy's rosidl (4.6.6) from the
# definitions of kinova-ros and of both ports, which all give the same values: pinned so that any change to a
# definition fails here.
KINOVA_HASHES = {
    "msg/JointVelocity": "RIHS01_987cd95f941959be7d3395f3dd2f534348bc2beb1d656ddf8bff78ecd3b8f1df",
    "msg/JointAngles": "RIHS01_2eec3403c783d331efdf8e7fd3f72dc755691ee85b6083a34efea1c45d23d59c",
    "msg/FingerPosition": "RIHS01_d9adbd6db7098edc5a1a3ad5f2df744f4b90496c0a018d7724b72ec5c2f2d3c4",
    "action/SetFingersPosition": "RIHS01_aa82f5f68f591fe0de2af053413624f614fc1630def6abee94ec97411b4decfb",
    "action/ArmJointAngles": "RIHS01_da97eaf6687b66629e38d5d13284d558f0e8753fd506670626beb9dd220caf20",
    "srv/HomeArm": "RIHS01_df62425bcda822e15f2c1df5227484f637f27e6150c3b279f4195d4dfdb8e212",
    "srv/Start": "RIHS01_3a83cd7ba16ecf04a8ce4a5088b54e52b339141438fcdd8a86b8d7a1d7ba5095",
    "srv/Stop": "RIHS01_5ba6f460887ef52cdffd64e2849d6f8ebd9243e17040c3945ba9d93fd6f158b7",
}

# .msg primitive types -> the type names of get_fields_and_field_types() (those used here).
PRIMITIVES = {"float32": "float", "float64": "double", "string": "string", "bool": "boolean",
              "int32": "int32", "uint32": "uint32", "uint8": "uint8"}
PARTS = {"msg": ("",), "srv": ("Request", "Response"), "action": ("Goal", "Result", "Feedback")}


def expected_fields(pkg, text):
    """One [(field, type)] per part of a .msg/.srv/.action text, types spelled as rosidl_generator_py does."""
    parts = []
    for block in text.split("---"):
        fields = []
        for line in block.splitlines():
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            typ, name = line.split()
            seq = typ.endswith("[]")
            typ = typ.removesuffix("[]")
            if typ in PRIMITIVES:
                typ = PRIMITIVES[typ]
            else:
                typ = typ if "/" in typ else f"{pkg}/{typ}"
            fields.append((name, f"sequence<{typ}>" if seq else typ))
        parts.append(fields)
    return parts


def slot_type_name(t):
    """A SLOT_TYPES entry (rosidl_parser.definition) in the spelling of get_fields_and_field_types()."""
    from rosidl_parser import definition as d
    if isinstance(t, d.UnboundedSequence):
        return f"sequence<{slot_type_name(t.value_type)}>"
    if isinstance(t, d.NamespacedType):
        return f"{t.namespaces[0]}/{t.name}"
    if isinstance(t, d.UnboundedString):
        return "string"
    if isinstance(t, d.BasicType):
        return t.typename
    raise AssertionError(f"unexpected slot type {t!r}")


def load(pkg, key):
    kind, name = key.split("/")
    module = __import__(f"{pkg}.{kind}", fromlist=[name])
    return getattr(module, name)


def type_description_file(pkg, key):
    """share/<pkg>/<kind>/<Type>.json of the prefix the package is imported from."""
    import importlib
    mod = importlib.import_module(pkg)
    candidates = [Path(p).resolve().parents[3] for p in mod.__path__]  # <prefix>/lib/pythonX.Y/site-packages/pkg
    candidates += [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in candidates:
        f = prefix / "share" / pkg / f"{key}.json"
        if f.is_file():
            return f
    raise AssertionError(f"no type description {pkg}/{key}.json under {candidates}")


def installed_hash(pkg, key):
    data = json.loads(type_description_file(pkg, key).read_text())
    full = f"{pkg}/{key}"
    hashes = [h["hash_string"] for h in data["type_hashes"] if h["type_name"] == full]
    assert len(hashes) == 1, data["type_hashes"]
    return hashes[0]


def check_definition(pkg, key, text):
    from rclpy.type_support import check_for_type_support
    iface = load(pkg, key)
    check_for_type_support(iface)  # the C type support loads
    kind = key.split("/")[0]
    want = expected_fields(pkg, text)
    assert len(want) == len(PARTS[kind]), f"{key}: {len(want)} parts in the reference text"
    for part, fields in zip(PARTS[kind], want):
        cls = getattr(iface, part) if part else iface
        label = f"{pkg}/{key}{'.' + part if part else ''}"
        got = list(cls.get_fields_and_field_types().items())
        assert got == fields, f"{label}: fields {got} != {fields}"
        slots = [s.removeprefix("_") for s in cls.__slots__ if s != "_check_fields"]
        assert slots == [n for n, _ in fields], f"{label}: slot order {slots}"
        slot_types = [slot_type_name(t) for t in cls.SLOT_TYPES]
        assert slot_types == [t for _, t in fields], f"{label}: slot types {slot_types}"
        cls()  # constructible with defaults


@pytest.mark.parametrize("key", sorted(KINOVA_ROS))
def test_kinova_msgs_match_kinova_ros(key):
    check_definition("kinova_msgs", key, KINOVA_ROS[key])


@pytest.mark.parametrize("key", sorted(KINOVA_HASHES))
def test_kinova_msgs_type_hash(key):
    assert installed_hash("kinova_msgs", key) == KINOVA_HASHES[key]


def test_tf_message_matches_jazzy():
    check_definition("tf2_msgs", "msg/TFMessage", TF2_MSGS["msg/TFMessage"])


def test_tf_message_type_hash_is_jazzys():
    assert installed_hash("tf2_msgs", "msg/TFMessage") == TF_MESSAGE_HASH


def test_advertised_type_hashes(monkeypatch):
    """The hash the compiled type support puts on the graph (what `ros2 topic info -v` shows) is the same."""
    import rclpy
    from kinova_msgs.msg import FingerPosition, JointAngles, JointVelocity
    from rclpy.context import Context
    from tf2_msgs.msg import TFMessage
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    expected = {TFMessage: TF_MESSAGE_HASH, JointVelocity: KINOVA_HASHES["msg/JointVelocity"],
                JointAngles: KINOVA_HASHES["msg/JointAngles"], FingerPosition: KINOVA_HASHES["msg/FingerPosition"]}
    context = Context()
    rclpy.init(context=context, domain_id=int(os.environ.get("QTREE_TEST_INTERFACES_DOMAIN_ID", "151")))
    try:
        node = rclpy.create_node(f"interfaces_probe_{os.getpid()}", context=context)
        try:
            for i, (msg_type, want) in enumerate(expected.items()):
                topic = f"/interfaces_probe_{os.getpid()}/t{i}"
                node.create_publisher(msg_type, topic, 1)
                mine = [e for e in node.get_publishers_info_by_topic(topic) if e.node_name == node.get_name()]
                assert len(mine) == 1, mine
                assert str(mine[0].topic_type_hash) == want, f"{msg_type.__name__}: {mine[0].topic_type_hash}"
        finally:
            node.destroy_node()
    finally:
        context.try_shutdown()


def test_qtree_relocation_msgs_still_import():
    from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
    from qtree_relocation_msgs.msg import ObjectArray, ObjectState
    from qtree_relocation_msgs.srv import PlanFeasibility
    from rclpy.type_support import check_for_type_support
    for iface in (PlanFeasibility, ObjectArray, ObjectState, RelocateObject, TrainPlanner):
        check_for_type_support(iface)


def test_object_state_carries_a_solid_primitive_and_is_the_one_msg_defs_defines():
    check_definition("qtree_relocation_msgs", "msg/ObjectState", OBJECT_STATE)
    source = Path(__file__).resolve().parent.parent / "msg_defs" / "qtree_relocation_msgs" / "msg" / "ObjectState.msg"
    assert expected_fields("qtree_relocation_msgs", source.read_text()) == \
        expected_fields("qtree_relocation_msgs", OBJECT_STATE)
    from qtree_relocation_msgs.msg import ObjectState
    from shape_msgs.msg import SolidPrimitive
    m = ObjectState()
    assert m.shape.type == 0 and SolidPrimitive.CYLINDER_HEIGHT == 0 and SolidPrimitive.CYLINDER_RADIUS == 1


def test_the_project_joint_velocity_is_gone():
    """The planner and the driver speak kinova_msgs/JointVelocity; the project's copy was removed."""
    import qtree_relocation_msgs.msg as m
    assert not hasattr(m, "JointVelocity")
