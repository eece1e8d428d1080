"""The Q-Tree as visualization_msgs markers (RViz): nodes by depth, edges coloured by their value Q(s, a).

Works on `QTree.to_state()` (the checkpoint format), so it needs no access to the tree's internals. Layout: a
vertical plane beside the shelf, one row per depth (the number of objects relocated, Eq. 8's sequence length),
nodes spread along y in allocation order. Edges to obstacle nodes form one LINE_LIST, coloured from red
(lowest Q) to green (highest); unfeasible edges (g_U, pruned) are left out; the greedy best sequence is drawn
as a thick LINE_STRIP and labelled with the objects' ids. Imports message types only (no rclpy).
"""
from __future__ import annotations

from geometry_msgs.msg import Point
from qtree_relocation_msgs.msg import ObjectArray
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from relocation_common.geometry import quat_xyzw
from relocation_common.ros_conversions import msg_to_objects

UNFEASIBLE = 0
ORIGIN = (0.35, -0.9, 1.0)  # m: top of the drawing (the root), in the base frame
ROW = 0.08  # m between depths
WIDTH = 1.8  # m across the widest row


def _colour(q: float, lo: float, hi: float) -> ColorRGBA:
    f = 0.5 if hi <= lo else (q - lo) / (hi - lo)
    return ColorRGBA(r=float(1.0 - f), g=float(f), b=0.1, a=0.9)


def tree_markers(state: dict, ids: tuple[str, ...], best: tuple[str, ...] | None, frame_id: str,
                 ns: str = "q_tree") -> MarkerArray:
    """MarkerArray of the tree in `state` (QTree.to_state()); `ids` maps action index -> object id; `best` is the
    learned sequence (ids, ending with the target) to highlight."""
    nodes = state["nodes"]
    pos: list = []
    per_depth: dict[int, int] = {}
    for n in nodes:
        per_depth[len(n["seq"])] = per_depth.get(len(n["seq"]), 0) + 1
    seen: dict[int, int] = {}
    for n in nodes:
        d = len(n["seq"])
        k = seen[d] = seen.get(d, -1) + 1
        y = ORIGIN[1] + WIDTH * ((k + 0.5) / per_depth[d])
        pos.append(Point(x=ORIGIN[0], y=float(y), z=float(ORIGIN[2] - ROW * d)))
    index = {tuple(n["seq"]): i for i, n in enumerate(nodes)}
    target = len(ids) - 1
    qs = [e[2] for n in nodes for e in n["edges"] if e[1] != UNFEASIBLE]
    lo, hi = (min(qs), max(qs)) if qs else (0.0, 1.0)

    def marker(mid: int, mtype: int) -> Marker:
        m = Marker(ns=ns, id=mid, type=mtype, action=Marker.ADD)
        m.header.frame_id = frame_id
        m.pose.orientation.w = 1.0
        return m

    dots = marker(0, Marker.SPHERE_LIST)
    dots.scale.x = dots.scale.y = dots.scale.z = 0.012
    dots.color = ColorRGBA(r=0.8, g=0.8, b=0.8, a=1.0)
    dots.points = pos
    edges = marker(1, Marker.LINE_LIST)
    edges.scale.x = 0.002
    goal = marker(2, Marker.SPHERE_LIST)  # target edges: where an episode can end
    goal.scale.x = goal.scale.y = goal.scale.z = 0.02
    goal.color = ColorRGBA(r=0.1, g=0.9, b=0.1, a=1.0)
    for i, n in enumerate(nodes):
        for a, label, q in n["edges"]:
            if label == UNFEASIBLE:
                continue
            if a == target:
                p = pos[i]
                goal.points.append(Point(x=p.x, y=p.y, z=p.z - ROW / 2))
                end = goal.points[-1]
            else:
                j = index.get(tuple(n["seq"]) + (a,))
                if j is None:
                    continue
                end = pos[j]
            edges.points += [pos[i], end]
            edges.colors += [_colour(q, lo, hi)] * 2
    out = MarkerArray(markers=[dots, edges, goal])
    if best:
        path = marker(3, Marker.LINE_STRIP)
        path.scale.x = 0.01
        path.color = ColorRGBA(r=1.0, g=0.85, b=0.0, a=1.0)
        seq: tuple[int, ...] = ()
        path.points.append(pos[0])
        for k, oid in enumerate(best):
            a = ids.index(oid)
            if a == target:
                p = path.points[-1]
                path.points.append(Point(x=p.x, y=p.y, z=p.z - ROW / 2))
            else:
                seq += (a,)
                if seq not in index:
                    break
                path.points.append(pos[index[seq]])
            t = marker(10 + k, Marker.TEXT_VIEW_FACING)
            t.pose.position = Point(x=path.points[-1].x, y=path.points[-1].y + 0.03, z=path.points[-1].z)
            t.scale.z = 0.03
            t.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
            t.text = oid
            out.markers.append(t)
        out.markers.append(path)
    return out


def scene_markers(scene: ObjectArray, sequence: tuple[str, ...], tree_state: dict | None = None,
                  ids: tuple[str, ...] = ()) -> MarkerArray:
    """The scene's objects (an ObjectArray, read through ros_conversions.msg_to_objects) as cylinders and boxes in
    their colour, each labelled with its place in the learned `sequence`; with a trained tree (`tree_state`,
    QTree.to_state(); `ids` its action -> id), the Q-Tree beside the shelf (tree_markers)."""
    arr = MarkerArray()
    if tree_state is not None:
        arr.markers += tree_markers(tree_state, ids, sequence, scene.header.frame_id).markers
    order = {o: k + 1 for k, o in enumerate(sequence)}
    for k, o in enumerate(msg_to_objects(scene, require_target=False)):
        box = o.shape == "box"
        m = Marker(ns="scene", id=k, type=Marker.CUBE if box else Marker.CYLINDER, action=Marker.ADD,
                   header=scene.header)
        c = o.centre()
        m.pose.position = Point(x=float(c[0]), y=float(c[1]), z=float(c[2]))
        q = m.pose.orientation
        q.x, q.y, q.z, q.w = quat_xyzw(o.rotation())
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in o.size)
        m.color.r, m.color.g, m.color.b, m.color.a = (*(float(v) for v in o.rgb), 1.0)
        t = Marker(ns="order", id=k, type=Marker.TEXT_VIEW_FACING, action=Marker.ADD, header=scene.header)
        t.pose.position = Point(x=float(c[0]), y=float(c[1]), z=float(o.top_z) + 0.04)
        t.pose.orientation.w = 1.0
        t.scale.z = 0.03
        t.color.r = t.color.g = t.color.b = t.color.a = 1.0
        t.text = f"{o.id} ({order[o.id]})" if o.id in order else o.id
        arr.markers += [m, t]
    return arr
