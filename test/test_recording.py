"""The run's recording (relocation_app.recording): a rosbag2 bag with MCAP storage and the retrieval's MP4.

Offline: message definitions as rosbag2 concatenates them, metadata.yaml, a bag written and read back (every message
decoded from the schema in the file), the video's frame count and duration. On a graph (the driver alone, a few
seconds): the topics the retrieval needs are in the bag, every message decodes, metadata.yaml agrees with the MCAP
file, the JPEG frames decode, the video lasts as long as the camera was recorded.

Decoding uses mcap_ros2 (the Python reader of the MCAP project). Its vendored rosidl_adapter refuses type names
with '_' (the names rosidl gives service events and action feedback messages, e.g. PlanFeasibility_Event), so
`decoder()` removes those underscores from the schema's names before generating the decoder; the field layout,
which is what decoding checks, is unchanged.
"""
import re
import time

import cv2
import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy")
pytest.importorskip("mcap.reader")
from mcap import reader as mcap_reader
from mcap_ros2._dynamic import generate_dynamic
from rclpy.serialization import serialize_message

from relocation_app import recording
from relocation_app.recording import (
    DELIMITER,
    BagWriter,
    RetrievalVideo,
    Status,
    full_definition,
    message_class,
    msg_text,
    qos_dict,
    to_yaml,
)

QOS = [{"history": "unknown", "depth": 0, "reliability": "reliable", "durability": "volatile",
        "deadline": {"sec": 9223372036, "nsec": 854775807}, "lifespan": {"sec": 9223372036, "nsec": 854775807},
        "liveliness": "automatic", "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
        "avoid_ros_namespace_conventions": False}]
METADATA_KEYS = ["version", "storage_identifier", "duration", "starting_time", "message_count",
                 "topics_with_message_count", "compression_format", "compression_mode", "relative_file_paths",
                 "files", "custom_data", "ros_distro"]


def decoder(schema):
    """A decoder for an MCAP schema (ros2msg), names with '_' made acceptable to mcap_ros2 (see the docstring)."""
    name, text = schema.name, schema.data.decode()
    for t in sorted(set(re.findall(r"\b[A-Z][A-Za-z0-9]*_[A-Za-z0-9_]+", name + "\n" + text)), key=len, reverse=True):
        name, text = name.replace(t, t.replace("_", "")), text.replace(t, t.replace("_", ""))
    return generate_dynamic(name, text)[name]


def read_bag(bag_dir):
    """(metadata.yaml's rosbag2_bagfile_information, MCAP summary, {topic: [decoded messages]}, {topic: [log times]},
    the rosbag2 metadata record)."""
    meta = yaml.safe_load((bag_dir / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    with open(bag_dir / meta["relative_file_paths"][0], "rb") as f:
        reader = mcap_reader.make_reader(f)
        summary = reader.get_summary()
        decoders, msgs, times = {}, {}, {}
        for schema, channel, message in reader.iter_messages():
            if schema.id not in decoders:
                decoders[schema.id] = decoder(schema)
            msgs.setdefault(channel.topic, []).append(decoders[schema.id](message.data))
            times.setdefault(channel.topic, []).append(message.log_time)
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    return meta, summary, msgs, times, records


def check_metadata(meta, summary, times, records) -> None:
    """metadata.yaml as rosbag2 (Jazzy, version 9) writes it, in agreement with the MCAP file."""
    assert list(meta) == METADATA_KEYS
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap" and meta["ros_distro"] == "jazzy"
    assert meta["compression_format"] == "" and meta["compression_mode"] == ""
    first, last = min(min(t) for t in times.values()), max(max(t) for t in times.values())
    assert meta["starting_time"]["nanoseconds_since_epoch"] == first
    assert meta["duration"]["nanoseconds"] == last - first
    assert meta["message_count"] == summary.statistics.message_count == sum(map(len, times.values()))
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    assert {k: v for k, v in counts.items() if v} == {k: len(v) for k, v in times.items()}
    (file,) = meta["files"]
    assert file["path"] == meta["relative_file_paths"][0] and file["message_count"] == meta["message_count"]
    by_topic = {c.topic: c for c in summary.channels.values()}
    for t in meta["topics_with_message_count"]:
        tm = t["topic_metadata"]
        assert tm["serialization_format"] == "cdr" and tm["offered_qos_profiles"]
        assert tm["type_description_hash"].startswith("RIHS01_")
        ch = by_topic[tm["name"]]
        assert summary.schemas[ch.schema_id].name == tm["type"]
        assert summary.schemas[ch.schema_id].encoding == "ros2msg"
        assert yaml.safe_load(ch.metadata["offered_qos_profiles"]) == tm["offered_qos_profiles"]
        assert ch.metadata["topic_type_hash"] == tm["type_description_hash"]
    assert yaml.safe_load(records["rosbag2"]["serialized_metadata"]) == meta


# ---------------------------------------------------------------------------------------------- offline
def test_definition_is_rosbag2s_concatenation():
    text = full_definition("sensor_msgs/msg/JointState")
    parts = text.split("\n" + DELIMITER)
    assert parts[0] == msg_text("sensor_msgs/msg/JointState")
    names = [p.split("\n", 1)[0] for p in parts[1:]]
    assert names == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]  # depth first, each once
    assert parts[1].split("\n", 1)[1] == msg_text("std_msgs/Header")
    # a type used twice (Header, Time in TFMessage's TransformStamped) is written once
    tf = full_definition("tf2_msgs/msg/TFMessage")
    assert tf.count("MSG: builtin_interfaces/Time") == 1 and tf.count("MSG: geometry_msgs/Vector3") == 1


def test_service_event_and_action_feedback_definitions():
    event = msg_text("qtree_relocation_msgs/srv/PlanFeasibility_Event")
    assert event.splitlines() == ["service_msgs/ServiceEventInfo info", "PlanFeasibility_Request[<=1] request",
                                  "PlanFeasibility_Response[<=1] response"]
    assert "string object_id" in msg_text("qtree_relocation_msgs/PlanFeasibility_Request")
    assert "uint8 label" in msg_text("qtree_relocation_msgs/PlanFeasibility_Response")
    full = full_definition("qtree_relocation_msgs/action/TrainPlanner_FeedbackMessage")
    assert "MSG: qtree_relocation_msgs/TrainPlanner_Feedback\n" in full and "MSG: unique_identifier_msgs/UUID" in full
    assert "string phase" in full and "bool execute" not in full
    assert message_class("qtree_relocation_msgs/action/TrainPlanner_FeedbackMessage").__name__ == \
        "TrainPlanner_FeedbackMessage"
    with pytest.raises(KeyError):
        msg_text("no_such_msgs/msg/Nothing")


def test_metadata_yaml_layout():
    text = to_yaml({"a": {"b": 1}, "files": [{"path": "x_0.mcap", "n": 2}], "empty": "", "none": None,
                    "seq": [], "flag": False, "name": "/tf"})
    assert text.splitlines() == ["a:", "  b: 1", "files:", "  - path: x_0.mcap", "    n: 2", 'empty: ""',
                                 "none: ~", "seq: []", "flag: false", "name: /tf"]
    from rclpy.qos import QoSProfile
    q = qos_dict(QoSProfile(depth=7))
    assert q["history"] == "keep_last" and q["depth"] == 7 and q["reliability"] == "reliable"
    assert yaml.safe_load(to_yaml([q])) == [q]


def test_bag_written_and_read_back(tmp_path):
    from qtree_relocation_msgs.action import TrainPlanner
    from qtree_relocation_msgs.srv import PlanFeasibility
    from sensor_msgs.msg import JointState
    bag = BagWriter(tmp_path / "bag")
    sent = {"/joint_states": [JointState(name=["a", "b"], position=[0.5 * i, -1.0]) for i in range(5)],
            "/task_planner/train/_action/feedback": [TrainPlanner.Impl.FeedbackMessage(
                feedback=TrainPlanner.Feedback(episode=3, q_sum=1.5, phase="training"))],
            "/motion_planner/plan_feasibility/_service_event": [PlanFeasibility.Event(
                request=[PlanFeasibility.Request(object_id="o2", removed_ids=["o1"])],
                response=[PlanFeasibility.Response(ok=True, label=1)])]}
    t = 1_700_000_000_000_000_000
    for name, msgs in sent.items():
        topic = bag.add_topic(name, recording.type_name_of(msgs[0]), QOS)
        for m in msgs:
            t += 10_000_000
            bag.write(topic, serialize_message(m), t)
    bag.close()
    assert sorted(p.name for p in (tmp_path / "bag").iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    meta, summary, msgs, times, records = read_bag(tmp_path / "bag")
    check_metadata(meta, summary, times, records)
    assert [list(m.position) for m in msgs["/joint_states"]] == [[0.5 * i, -1.0] for i in range(5)]
    (fb,) = msgs["/task_planner/train/_action/feedback"]
    assert (fb.feedback.episode, fb.feedback.phase) == (3, "training")
    (ev,) = msgs["/motion_planner/plan_feasibility/_service_event"]
    assert ev.request[0].object_id == "o2" and list(ev.request[0].removed_ids) == ["o1"]
    assert ev.response[0].label == 1


def test_video_frame_count_and_duration(tmp_path):
    video = RetrievalVideo(tmp_path / "v.mp4", fps=5.0)
    t0, rng = 100.0, np.random.default_rng(0)
    times = t0 + np.cumsum(rng.uniform(0.3, 0.7, 12))  # a 2 Hz camera with jitter
    for i, t in enumerate(times):
        frame = np.full((120, 160, 3), 20 * i, np.uint8)
        video.add(frame, t, Status(phase="executing", relocating="o2", relocations=1, step="carry").lines(t - t0))
    info = video.close(times[-1] + 1.0)
    expected = round((times[-1] + 1.0 - times[0]) * 5.0)
    assert info["frames"] == expected and info["duration_s"] == pytest.approx(expected / 5.0)
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(5.0)
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == expected


def test_no_frames_no_video(tmp_path):
    assert RetrievalVideo(tmp_path / "v.mp4").close(1.0)["frames"] == 0
    assert not (tmp_path / "v.mp4").exists()


# ---------------------------------------------------------------------------------------------- on a graph
@pytest.mark.graph
def record_until(rec, least_counts: dict, least: float, timeout: float = 60.0):
    """Record for at least `least` s and until the bag holds `least_counts` messages per topic (a key matches the
    topics ending with it), at most `timeout` s: the driver publishes at rates of simulated time, which runs slower
    than the wall clock on a loaded machine, so a fixed recording time holds a load-dependent number of messages.
    The counts reached, or None at the timeout."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        time.sleep(0.2)
        topics = {name: t.count for name, t in list(rec.bag.topics.items())}
        counts = {k: max((c for name, c in topics.items() if name.endswith(k)), default=0) for k in least_counts}
        if time.monotonic() - t0 >= least and all(counts[k] >= n for k, n in least_counts.items()):
            return counts
    return None


def test_driver_run_recorded(tmp_path):
    from ros_procs import REPO, RosGraph
    with RosGraph(tmp_path / "graph") as g:
        g.start("jaco2_sim_driver.driver_node", params_file=REPO / "config" / "jaco2_sim_driver.yaml",
                params={"camera_rate": 2.0})
        g.probe.collect("/sim/objects", recording.message_class("qtree_relocation_msgs/msg/ObjectArray")).wait(
            timeout=60)  # the driver is up
        rec = recording.RunRecorder(tmp_path / "bag", video=tmp_path / "run.mp4", domain_id=g.domain_id).start()
        counts = record_until(rec, {"/camera/color/image_raw/compressed": 8, "joint_state": 101}, least=6.0)
        summary = rec.stop()
    assert counts is not None, "the bag did not reach 8 camera frames and 101 joint states in 60 s"
    meta, mcap_summary, msgs, times, records = read_bag(tmp_path / "bag")
    check_metadata(meta, mcap_summary, times, records)
    for topic in ("/tf", "/tf_static", "/robot_description", "/sim/objects", "/camera/color/camera_info",
                  "/camera/color/image_raw/compressed"):
        assert msgs.get(topic), f"nothing on {topic}: {sorted(msgs)}"
    states = [t for t in msgs if t.endswith(("/joint_state", "/joint_states"))]
    assert states and len(msgs[states[0]]) > 100  # the driver's rate is test_sim_driver_core's
    assert all(len(m.name) == len(m.position) > 0 for m in msgs[states[0]])
    assert "/clock" not in msgs and "/camera/depth/image_rect_raw" not in msgs
    jpg = msgs["/camera/color/image_raw/compressed"][-1]
    img = cv2.imdecode(np.frombuffer(bytes(jpg.data), np.uint8), cv2.IMREAD_COLOR)
    info = msgs["/camera/color/camera_info"][-1]
    assert img.shape == (info.height, info.width, 3) and "jpeg" in jpg.format
    assert summary["bag"]["messages"] == meta["message_count"]
    assert summary["bag"]["bytes"] == sum(f.stat().st_size for f in (tmp_path / "bag").iterdir())
    # the video: from the first camera frame to the end of the recording, at its frame rate
    video = summary["video"]
    cap = cv2.VideoCapture(str(tmp_path / "run.mp4"))
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == video["frames"] == round(video["duration_s"] * video["fps"])
    camera = times["/camera/color/image_raw/compressed"]
    recorded = (max(max(t) for t in times.values()) - camera[0]) * 1e-9
    assert video["duration_s"] == pytest.approx(recorded, abs=0.6)
    assert len(camera) >= 8
