"""Recording a run: a rosbag2 bag (MCAP storage) of the graph's topics and an MP4 of the retrieval.

    rec = RunRecorder(out / "bag", video=out / "retrieval.mp4", domain_id=graph.domain_id,
                      video_from_phase="executing").start()
    ...                                  # the run
    summary = rec.stop()                 # topics, message counts, bytes, video frames and duration

The bag is what `ros2 bag record -a --include-hidden-topics -s mcap` writes in Jazzy, so that `ros2 bag play`
and Foxglove open it as it is: a directory with `<dir>_0.mcap` and `metadata.yaml` (rosbag2 version 9); profile
`ros2`; one channel per topic, cdr messages; a schema per type with the full `.msg` text of the type and of every
type it uses (encoding ros2msg, as rosbag2_cpp's LocalMessageDefinitionSource concatenates them); the publishers'
offered QoS and type hash in the channel metadata; receive time as log time, the publisher's time as publish
time; the bag's metadata also in a `rosbag2` metadata record. Differences, all for size and time:
- chunks are zstd-compressed (what the mcap plugin's `zstd_fast` preset does; every MCAP reader decompresses);
- the colour camera is recorded as sensor_msgs/CompressedImage (JPEG) on `<topic>/compressed` (image_transport's
  name); other sensor_msgs/Image topics (the depth image, 1.2 MB a frame) are left out, as are /clock and
  /parameter_events;
- of the hidden topics, only action feedback and status and service events (e.g. the task planner's
  PlanFeasibility queries and answers) are recorded; their definitions are built from the `.action` / `.srv` files
  (rosbag2 in Jazzy leaves them empty).

The video: the colour camera with the phase (TrainPlanner feedback), the object being relocated
(/task_planner/relocating) and the motion planner's step (RelocateObject feedback) written on each frame, at a fixed
frame rate, each camera frame held until the next one, so its duration is the recorded time. MPEG-4 Part 2 (mp4v):
the codec opencv-python-headless writes here (no H.264 encoder in the wheel).

Subscriptions are generic (raw bytes, the type found by topic discovery every `discovery_period` s); the recorder
runs its own node in its own rclpy context and thread.
"""
from __future__ import annotations

import importlib
import json
import os
import re
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from rclpy.node import Node

ROS_DISTRO = "jazzy"
BAG_VERSION = 9  # rosbag2_storage BagMetadata.version in Jazzy
CAMERA = "/camera/color/image_raw"
SKIPPED = ("/clock", "/parameter_events")
HIDDEN_KEPT = ("/_action/feedback", "/_action/status", "/_service_event")
DEPTH = 100  # subscription queue: bursts (latched topics, logs) are not dropped
DELIMITER = "=" * 80 + "\n"
PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
              "int64", "uint64", "string"}
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")  # rosbag2's MSG_FIELD_TYPE_REGEX
_SRV_PART = re.compile(r"(.+)_(Request|Response|Event)$")
_ACTION_PART = re.compile(r"(.+)_(Goal|Result|Feedback|FeedbackMessage)$")


# ---------------------------------------------------------------------------------------------- message types
def _share_dirs() -> list[Path]:
    """Install prefixes' share directories: AMENT_PREFIX_PATH (a sourced ROS install), then this interpreter's
    prefix (the ros-jazzy-* wheels install their interface files into <venv>/share)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    return [Path(p) / "share" for p in prefixes]


def _interface_file(package: str, kind: str, name: str) -> Path | None:
    for share in _share_dirs():
        f = share / package / kind / name
        if f.is_file():
            return f
    return None


def _split_type(type_name: str) -> tuple[str, str, str]:
    """'pkg/msg/T' -> (pkg, 'msg', T); 'pkg/T' -> (pkg, '', T)."""
    parts = type_name.split("/")
    if len(parts) == 2:
        return parts[0], "", parts[1]
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    raise ValueError(f"not a ROS type name: {type_name!r}")


def _sections(path: Path) -> list[str]:
    return re.split(r"^---[ \t]*\n?", path.read_text(), flags=re.MULTILINE)


def msg_text(type_name: str) -> str:
    """The .msg text of a type: share/<pkg>/msg/<T>.msg; for a service's or an action's parts (T_Request,
    T_Response, T_Event; T_Goal, T_Result, T_Feedback, T_FeedbackMessage) the section of the .srv / .action file or
    the message rosidl generates around them. KeyError when there is none."""
    pkg, _, name = _split_type(type_name)
    f = _interface_file(pkg, "msg", f"{name}.msg")
    if f is not None:
        return f.read_text()
    m = _SRV_PART.match(name)
    f = _interface_file(pkg, "srv", f"{m.group(1)}.srv") if m else None
    if m and f is not None:
        base, part = m.groups()
        if part == "Event":
            return (f"service_msgs/ServiceEventInfo info\n{base}_Request[<=1] request\n"
                    f"{base}_Response[<=1] response\n")
        return _sections(f)[0 if part == "Request" else 1]
    m = _ACTION_PART.match(name)
    f = _interface_file(pkg, "action", f"{m.group(1)}.action") if m else None
    if m and f is not None:
        base, part = m.groups()
        if part == "FeedbackMessage":
            return f"unique_identifier_msgs/UUID goal_id\n{base}_Feedback feedback\n"
        return _sections(f)[("Goal", "Result", "Feedback").index(part)]
    raise KeyError(f"no interface definition found for {type_name} (searched {', '.join(map(str, _share_dirs()))})")


def _dependencies(text: str, package: str) -> list[str]:
    deps = set()
    for m in _FIELD_TYPE.finditer(text):
        t = m.group(1)
        if t not in PRIMITIVES:
            deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)  # std::set order


def full_definition(type_name: str) -> str:
    """The ros2msg schema text rosbag2 writes: the type's .msg text, then, depth first in sorted order and each
    once, every type it uses, each after a line of 80 '=' and a line 'MSG: <type as written in the field>'."""
    seen: set[str] = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise RecursionError(f"definition of {type_name} nests too deep")
        text = msg_text(name)
        for dep in _dependencies(text, _split_type(name)[0]):
            if dep not in seen:
                seen.add(dep)
                text += "\n" + DELIMITER + f"MSG: {dep}\n" + append(dep, depth - 1)
        return text

    return append(type_name, 50)


def type_hash(type_name: str) -> str:
    """RIHS01_... from the type description (.json) rosidl installs beside the interface file; '' if none."""
    pkg, kind, name = _split_type(type_name)
    pattern = (_SRV_PART if kind == "srv" else _ACTION_PART if kind == "action" else None)
    m = pattern.match(name) if pattern else None
    base = m.group(1) if m else name
    f = _interface_file(pkg, kind or "msg", f"{base}.json")
    if f is None:
        return ""
    for h in json.loads(f.read_text()).get("type_hashes", []):
        if h.get("type_name") == f"{pkg}/{kind or 'msg'}/{name}":
            return h.get("hash_string", "")
    return ""


def type_name_of(msg) -> str:
    """'pkg/msg/T' (or srv/, action/) of a message instance or class."""
    cls = msg if isinstance(msg, type) else type(msg)
    pkg, kind = cls.__module__.split(".")[:2]
    return f"{pkg}/{kind}/{cls.__name__}"


def message_class(type_name: str):
    """The Python class of a type name as topic discovery gives it ('pkg/msg/T', 'pkg/srv/T_Event', ...)."""
    pkg, kind, name = _split_type(type_name)
    mod = importlib.import_module(f"{pkg}.{kind or 'msg'}")
    if kind in ("", "msg"):
        return getattr(mod, name)
    m = (_SRV_PART if kind == "srv" else _ACTION_PART).match(name)
    if m is None:
        raise ValueError(f"unsupported type {type_name}")
    base = getattr(mod, m.group(1))
    return base.Impl.FeedbackMessage if m.group(2) == "FeedbackMessage" else getattr(base, m.group(2))


# ---------------------------------------------------------------------------------------------- metadata.yaml
def qos_dict(q) -> dict:
    """An rclpy QoSProfile as rosbag2 (version 9) writes it: policies by rmw name, durations as sec/nsec."""
    def dur(d) -> dict:
        ns = int(d.nanoseconds)
        return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}

    return {"history": q.history.name.lower(), "depth": int(q.depth), "reliability": q.reliability.name.lower(),
            "durability": q.durability.name.lower(), "deadline": dur(q.deadline), "lifespan": dur(q.lifespan),
            "liveliness": q.liveliness.name.lower(), "liveliness_lease_duration": dur(q.liveliness_lease_duration),
            "avoid_ros_namespace_conventions": bool(q.avoid_ros_namespace_conventions)}


def _scalar(v) -> str:
    import yaml
    if v is None:
        return "~"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return str(v)
    s = str(v)
    plain = s and s.strip() == s and not re.search(r"[:#\[\]{},&*!|>'\"%@`]", s) and yaml.safe_load(s) == s
    return s if plain else json.dumps(s)


def to_yaml(v, indent: int = 0) -> str:
    """Block YAML laid out as yaml-cpp emits it (rosbag2's writer): sequences indented under their key."""
    pad = " " * indent
    if isinstance(v, dict):
        out = []
        for k, x in v.items():
            if isinstance(x, (dict, list)) and x:
                out.append(f"{pad}{k}:\n{to_yaml(x, indent + 2)}")
            else:
                out.append(f"{pad}{k}: {'[]' if x == [] else '{}' if x == {} else _scalar(x)}")
        return "\n".join(out)
    if isinstance(v, list):
        return "\n".join(f"{pad}- " + to_yaml(x, indent + 2).lstrip() if isinstance(x, (dict, list)) else
                         f"{pad}- {_scalar(x)}" for x in v)
    return pad + _scalar(v)


# ---------------------------------------------------------------------------------------------- the bag
@dataclass
class _Topic:
    name: str
    type: str
    qos: list
    type_hash: str
    channel: int = 0
    count: int = 0


class BagWriter:
    """A rosbag2 bag directory with MCAP storage: `<dir>/<dir name>_0.mcap` and `<dir>/metadata.yaml`."""

    def __init__(self, bag_dir: Path, chunk_size: int = 1 << 20):
        from mcap.writer import CompressionType, Writer
        self.dir = Path(bag_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        for old in list(self.dir.glob("*.mcap")) + [self.dir / "metadata.yaml"]:
            old.unlink(missing_ok=True)  # a previous run in the same place
        self.file = f"{self.dir.name}_0.mcap"
        self._stream = open(self.dir / self.file, "wb")
        self._mcap = Writer(self._stream, chunk_size=chunk_size, compression=CompressionType.ZSTD,
                            enable_crcs=True)
        self._mcap.start(profile="ros2", library="qtree_relocation recorder (rosbag2 mcap layout)")
        self.topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
        self.first: int | None = None  # log time (ns) of the first message
        self.last: int | None = None
        self.count = 0

    def add_topic(self, name: str, type_name: str, qos: list[dict], hash_: str = "") -> _Topic:
        """Schema (once per type) and channel; KeyError when the type's definition cannot be found."""
        if type_name not in self._schemas:
            self._schemas[type_name] = self._mcap.register_schema(type_name, "ros2msg",
                                                                  full_definition(type_name).encode())
        t = _Topic(name, type_name, qos, hash_ or type_hash(type_name))
        t.channel = self._mcap.register_channel(name, "cdr", self._schemas[type_name], {
            "offered_qos_profiles": to_yaml(qos), "topic_type_hash": t.type_hash})
        self.topics[name] = t
        return t

    def write(self, topic: _Topic, data: bytes, log_ns: int, publish_ns: int = 0) -> None:
        """Add one serialized message of `topic` (log and publish time in ns)."""
        self._mcap.add_message(topic.channel, log_time=log_ns, data=data, publish_time=publish_ns or log_ns)
        topic.count += 1
        self.count += 1
        self.first = log_ns if self.first is None else min(self.first, log_ns)
        self.last = log_ns if self.last is None else max(self.last, log_ns)

    def metadata(self) -> dict:
        """rosbag2's metadata (metadata.yaml) of what was written so far."""
        start, duration = (self.first or 0), (self.last or 0) - (self.first or 0)
        topics = [{"topic_metadata": {"name": t.name, "type": t.type, "serialization_format": "cdr",
                                      "offered_qos_profiles": t.qos, "type_description_hash": t.type_hash},
                   "message_count": t.count} for t in self.topics.values()]
        return {"version": BAG_VERSION, "storage_identifier": "mcap", "duration": {"nanoseconds": duration},
                "starting_time": {"nanoseconds_since_epoch": start}, "message_count": self.count,
                "topics_with_message_count": topics, "compression_format": "", "compression_mode": "",
                "relative_file_paths": [self.file],
                "files": [{"path": self.file, "starting_time": {"nanoseconds_since_epoch": start},
                           "duration": {"nanoseconds": duration}, "message_count": self.count}],
                "custom_data": None, "ros_distro": ROS_DISTRO}

    def close(self) -> dict:
        """Finish the MCAP file (summary, statistics, the rosbag2 metadata record) and write metadata.yaml."""
        meta = self.metadata()
        self._mcap.add_metadata("rosbag2", {"serialized_metadata": to_yaml(meta) + "\n"})
        self._mcap.finish()
        self._stream.close()
        (self.dir / "metadata.yaml").write_text(to_yaml({"rosbag2_bagfile_information": meta}) + "\n")
        return meta


# ---------------------------------------------------------------------------------------------- the video
class RetrievalVideo:
    """An MP4 at a fixed rate from frames arriving at any rate: each frame is shown until the next one."""

    def __init__(self, path: Path, fps: float = 5.0):
        self.path, self.fps = Path(path), float(fps)
        self._writer: Any = None  # a cv2.VideoWriter from the first frame (its size); cv2 is imported lazily
        self._prev: np.ndarray | None = None
        self._t0 = 0.0  # time of the first frame
        self.frames = 0

    def add(self, bgr: np.ndarray, t: float, lines: list[str]) -> None:
        """Add a camera frame taken at `t` (s) with its caption; the previous frame is repeated up to `t`."""
        import cv2
        if self._writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            h, w = bgr.shape[:2]
            self._writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter.fourcc(*"mp4v"), self.fps, (w, h))
            if not self._writer.isOpened():
                raise RuntimeError(f"OpenCV cannot write {self.path} (mp4v)")
            self._t0 = t
        self._fill(t)
        self._prev = _caption(bgr.copy(), lines)
        self._write(self._prev)

    def _fill(self, t: float) -> None:
        while self._prev is not None and self.frames < round((t - self._t0) * self.fps):
            self._write(self._prev)

    def _write(self, frame) -> None:
        self._writer.write(frame)
        self.frames += 1

    def close(self, t_end: float) -> dict:
        """Finish the video at `t_end` (s); its path, frame count, rate and length."""
        if self._writer is None:
            return {"path": None, "frames": 0, "fps": self.fps, "duration_s": 0.0}
        self._fill(t_end)
        self._writer.release()
        return {"path": str(self.path), "frames": self.frames, "fps": self.fps,
                "duration_s": round(self.frames / self.fps, 2)}


def _caption(img: np.ndarray, lines: list[str]) -> np.ndarray:
    import cv2
    h = 12 + 26 * len(lines)
    img[:h] = (img[:h] * 0.35).astype(img.dtype)  # a dark band: the text reads on any background
    for i, text in enumerate(lines):
        cv2.putText(img, text, (10, 28 + 26 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.65, (255, 255, 255), 2, cv2.LINE_AA)
    return img


def image_to_bgr(msg) -> np.ndarray:
    """sensor_msgs/Image (rgb8, bgr8, rgba8, bgra8, mono8) as an OpenCV BGR array."""
    import cv2
    ch = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1}.get(msg.encoding)
    if ch is None:
        raise ValueError(f"image encoding {msg.encoding!r} not supported")
    a = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.step)[:, :msg.width * ch]
    a = a.reshape(msg.height, msg.width, ch)
    conv = {"rgb8": cv2.COLOR_RGB2BGR, "rgba8": cv2.COLOR_RGBA2BGR, "bgra8": cv2.COLOR_BGRA2BGR,
            "mono8": cv2.COLOR_GRAY2BGR}.get(msg.encoding)
    return cv2.cvtColor(a, conv) if conv is not None else a.copy()


# ---------------------------------------------------------------------------------------------- the recorder
def _stamps(info) -> tuple[int, int]:
    """(log time, publish time) in ns since the epoch: when DDS received the message (rosbag2: when it was
    taken) and the publisher's source time."""
    received = int(info.get("received_timestamp", 0)) if info else 0
    return received or time.time_ns(), int(info.get("source_timestamp", 0)) if info else 0


@dataclass
class Status:
    """What the frames say: TrainPlanner feedback, the object relocated, the RelocateObject step."""
    phase: str = ""
    episode: int = 0
    relocating: str = ""
    relocations: int = 0
    step: str = ""
    progress: float = 0.0

    def lines(self, elapsed: float) -> list[str]:
        """The caption of a video frame `elapsed` s into the run."""
        head = self.phase or "recording"
        if self.phase in ("training", "exact optimum"):
            head += f": episode {self.episode}" if self.phase == "training" else ""
        elif self.relocating:
            head += f": relocation {self.relocations}, {self.relocating}"
            if self.step:
                head += f" - {self.step} ({self.progress * 100:.0f} %)"
        return [head, f"t = {elapsed:5.1f} s"]


class RunRecorder:
    """Records the graph on `domain_id` (None: ROS_DOMAIN_ID) into a bag, and the camera into a video.

    `video_from_phase`: frames go into the video from the first TrainPlanner feedback in that phase on (the demo:
    "executing"); None: from the first frame."""

    def __init__(self, bag_dir: Path, video: Path | None = None, *, domain_id: int | None = None,
                 video_from_phase: str | None = None, camera: str = CAMERA, fps: float = 5.0,
                 jpeg_quality: int = 80, discovery_period: float = 0.5, poll_period: float = 0.05):
        self.bag_dir, self.camera, self.jpeg_quality = Path(bag_dir), camera, jpeg_quality
        self.domain_id, self.video_from_phase = domain_id, video_from_phase
        self.discovery_period, self.poll_period = discovery_period, poll_period
        self.video = RetrievalVideo(video, fps) if video is not None else None
        self.status = Status()
        self.skipped: dict[str, str] = {}  # topic -> why it is not recorded
        self.errors: dict[str, str] = {}   # topic -> the first error handling one of its messages
        self._seen: set[str] = set()
        self._video_on = video_from_phase is None
        self.bag: BagWriter | None = None
        self._node: Node | None = None

    # -- life cycle ---------------------------------------------------------------------------------------------
    def start(self) -> "RunRecorder":
        """Open the bag and start the recording thread on a private rclpy context."""
        import rclpy
        from rclpy.signals import SignalHandlerOptions
        self.bag = BagWriter(self.bag_dir)
        self._t0 = time.monotonic()
        self._context = rclpy.Context()
        domain_id = None if self.domain_id is None else int(self.domain_id)
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO, domain_id=domain_id)
        self._node = rclpy.create_node("run_recorder", context=self._context, enable_rosout=False,
                                       start_parameter_services=False)
        self._subs: list[tuple] = []  # (subscription, handler(msg, info))
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="run_recorder", daemon=True)
        self._thread.start()
        return self

    def _loop(self) -> None:
        """Discovery every discovery_period, then every subscription drained, every poll_period. No executor: an
        rclpy executor costs about 0.3 ms of Python per message (measured on the driver's topics, 350 messages/s:
        12 % of a core; taken in bulk here: 4 %). DDS queues the messages meanwhile (depth 100)."""
        next_discovery = 0.0
        while not self._stopping.is_set():
            if time.monotonic() >= next_discovery:
                self._discover()
                next_discovery = time.monotonic() + self.discovery_period
            self._drain()
            self._stopping.wait(self.poll_period)
        self._drain()

    def _drain(self) -> None:
        for sub, handler in self._subs:
            while True:
                with sub.handle:
                    taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    break
                try:
                    handler(*taken)
                except Exception as e:  # one bad message (an image in an odd encoding) stops nothing
                    self.errors[sub.topic_name] = self.errors.get(sub.topic_name) or f"{type(e).__name__}: {e}"

    def stop(self) -> dict:
        """Stop recording; close the bag and the video. A summary: bag (files, bytes, messages per topic), video."""
        t_end = time.time()  # the bag's clock (_stamps), as the video's frames
        self._stopping.set()
        self._thread.join(timeout=10.0)
        self._ros().destroy_node()
        self._context.try_shutdown()
        bag = self._bag()
        meta = bag.close()
        size = sum(f.stat().st_size for f in bag.dir.iterdir() if f.is_file())
        return {"bag": {"path": str(bag.dir), "bytes": size, "messages": meta["message_count"],
                        "duration_s": round(meta["duration"]["nanoseconds"] * 1e-9, 2),
                        "topics": {t.name: t.count for t in bag.topics.values()}, "skipped": self.skipped,
                        "errors": self.errors},
                "video": self.video.close(t_end) if self.video is not None else None}

    def _ros(self) -> Node:
        if self._node is None:
            raise RuntimeError("RunRecorder: call start() first")
        return self._node

    def _bag(self) -> BagWriter:
        if self.bag is None:
            raise RuntimeError("RunRecorder: call start() first")
        return self.bag

    def __enter__(self) -> "RunRecorder":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.summary = self.stop()

    # -- topics -------------------------------------------------------------------------------------------------
    def _discover(self) -> None:
        for name, types in self._ros().get_topic_names_and_types():
            if name in self._seen:
                continue
            why = self._excluded(name, types)
            if why:
                self._seen.add(name)
                self.skipped[name] = why
                continue
            pubs = self._ros().get_publishers_info_by_topic(name)
            if not pubs:
                continue  # subscribers only: wait for a publisher (its QoS decides ours)
            self._seen.add(name)
            try:
                self._subscribe(name, types[0], pubs)
            except (KeyError, ValueError, ImportError, AttributeError) as e:
                self.skipped[name] = f"cannot record: {e}"

    def _excluded(self, name: str, types: list[str]) -> str:
        if name in SKIPPED:
            return "not recorded (simulation clock / parameter events)"
        if any(part.startswith("_") for part in name.split("/")) and not name.endswith(HIDDEN_KEPT):
            return "hidden topic"
        if types[0] == "sensor_msgs/msg/Image" and name != self.camera:
            return "raw image (size): not recorded"
        return ""

    def _subscribe(self, name: str, type_name: str, pubs) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        offered = [p.qos_profile for p in pubs]
        qos = QoSProfile(depth=DEPTH)
        qos.reliability = (ReliabilityPolicy.RELIABLE if all(q.reliability == ReliabilityPolicy.RELIABLE
                                                             for q in offered) else ReliabilityPolicy.BEST_EFFORT)
        qos.durability = (DurabilityPolicy.TRANSIENT_LOCAL if all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL
                                                                  for q in offered) else DurabilityPolicy.VOLATILE)
        hashes = {str(p.topic_type_hash) for p in pubs} - {"INVALID"}
        profiles = [qos_dict(q) for q in offered]
        if name == self.camera:
            from sensor_msgs.msg import CompressedImage, Image
            topic = self._bag().add_topic(f"{name}/compressed", "sensor_msgs/msg/CompressedImage", profiles)
            sub = self._ros().create_subscription(Image, name, lambda m: None, qos)
            self._subs.append((sub, lambda m, i: self._on_image(topic, CompressedImage, m, i)))
            return
        topic = self._bag().add_topic(name, type_name, profiles, next(iter(hashes), ""))
        watch = self._watcher(name, type_name)
        sub = self._ros().create_subscription(message_class(type_name), name, lambda m: None, qos, raw=True)
        self._subs.append((sub, lambda raw, info: self._on_raw(topic, watch, raw, info)))

    def _on_raw(self, topic: _Topic, watch, raw: bytes, info) -> None:
        self._bag().write(topic, raw, *_stamps(info))
        if watch is not None:
            watch(raw)

    def _on_image(self, topic: _Topic, compressed_type, msg, info) -> None:
        import cv2
        from rclpy.serialization import serialize_message
        bgr = image_to_bgr(msg)
        ok, jpg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg_quality)])
        if ok:
            out = compressed_type(header=msg.header, format=f"{msg.encoding}; jpeg compressed bgr8")
            out.data = jpg.tobytes()
            self._bag().write(topic, serialize_message(out), *_stamps(info))
        if self.video is not None and self._video_on:  # on the bag's clock: the frame's log time (its first
            # frame's time was when this callback got to it, after cv2's import under load: a video 1.3 s short)
            self.video.add(bgr, _stamps(info)[0] * 1e-9, self.status.lines(time.monotonic() - self._t0))

    # -- what the frames say ------------------------------------------------------------------------------------
    def _watcher(self, name: str, type_name: str):
        """A decoder for the topics that drive the captions (None for the others)."""
        from rclpy.serialization import deserialize_message
        if type_name == "qtree_relocation_msgs/action/TrainPlanner_FeedbackMessage":
            cls, fn = message_class(type_name), self._on_train_feedback
        elif type_name == "qtree_relocation_msgs/action/RelocateObject_FeedbackMessage":
            cls, fn = message_class(type_name), self._on_relocate_feedback
        elif name == "/task_planner/relocating" and type_name == "std_msgs/msg/String":
            cls, fn = message_class(type_name), self._on_relocating
        else:
            return None
        return lambda raw: fn(deserialize_message(raw, cls))

    def _on_train_feedback(self, m) -> None:
        s = self.status
        if m.feedback.phase != s.phase:
            s.step, s.progress = "", 0.0
        s.phase, s.episode = m.feedback.phase, m.feedback.episode
        if self.video_from_phase is not None and s.phase == self.video_from_phase:
            self._video_on = True

    def _on_relocate_feedback(self, m) -> None:
        self.status.step, self.status.progress = m.feedback.phase, float(m.feedback.progress)

    def _on_relocating(self, m) -> None:
        self.status.relocating, self.status.relocations = m.data, self.status.relocations + 1
        self.status.step, self.status.progress = "", 0.0
