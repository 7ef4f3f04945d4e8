"""Writing a drive as a log in each format the readers take, through the same libraries (the ``logs`` extra), and its
mapping: the round-trip tests write a simulated run's truth and readings with it, and ``netsetest log-example``
(logs/example.py) the synthetic example drives of docs/your-log.md.

A :class:`DriveTable` holds the channels on one time base (seconds); each writer lays them out as the field records
them: a CSV or Parquet table with a time column; an MDF4 file with one channel group; a ROS 2 bag (MCAP or sqlite3)
with a ``sensor_msgs/msg/Imu`` per yaw-rate sensor (``angular_velocity.z``, header-stamped), the speed as a
``nav_msgs/msg/Odometry`` (``twist.twist.linear.x``), the steering and the reference as ``std_msgs/msg/Float64`` (or
the reference as one INS topic, a ``geometry_msgs/msg/Vector3Stamped``: ``DriveTable.ins_message``).
"""

from __future__ import annotations

import heapq
import shutil
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from netsetest.extras import require

WRITE_FORMATS = ("csv", "parquet", "mdf4", "rosbag-mcap", "rosbag-sqlite3")
SUFFIX = {"csv": ".csv", "parquet": ".parquet", "mdf4": ".mf4", "rosbag-mcap": "", "rosbag-sqlite3": ""}  # a bag is a directory
SPEED_TOPIC, STEERING_TOPIC, BETA_TOPIC, R_TOPIC = "/vehicle/odom", "/vehicle/steering", "/ins/beta", "/ins/yaw_rate"
INS_TOPIC = "/ins/state"  # DriveTable.ins_message: one geometry_msgs/msg/Vector3Stamped, β in vector.x, r in vector.z


def imu_topic(node: int) -> str:
    return f"/imu{node}/data"


@dataclass(frozen=True)
class DriveTable:
    """Channels of a drive in SI units: ``t`` [s], ``speed`` [m/s], ``steering`` road-wheel [rad], per node its
    yaw rate [rad/s] (its stamps may differ: ``yaw_t``), and a reference β [rad], r [rad/s] (None: none)."""

    t: np.ndarray
    speed: np.ndarray
    steering: np.ndarray
    yaw: dict[int, np.ndarray]
    beta: np.ndarray | None = None
    r: np.ndarray | None = None
    yaw_t: dict[int, np.ndarray] = field(default_factory=dict)  # a sensor's own stamps (jitter); default t
    description: str = ""  # what the drive is (an MDF4 comment, a bag's metadata: "synthetic: …")
    ins_message: bool = False  # a bag: the reference as one INS message (INS_TOPIC) instead of a Float64 topic each

    def stamps(self, node: int) -> np.ndarray:
        return self.yaw_t.get(node, self.t)


def from_truth(truth: list[dict], tau_s: float, description: str = "") -> DriveTable:
    """A simulated run's truth entries (a record's, in step order; their node maps keyed by id, as the record's JSON
    or a loaded record has them) as a drive: each sensor's reading without its fault (``y_nofault``: the run injects
    the profile's fault again), the speed and steering, and x as the reference."""
    t = np.arange(len(truth)) * tau_s
    keys = sorted(truth[0]["y_nofault"], key=int)
    return DriveTable(
        t=t,
        speed=np.array([e["vx"] for e in truth]),
        steering=np.array([e["u"] for e in truth]),
        yaw={int(i): np.array([e["y_nofault"][i] for e in truth]) for i in keys},
        beta=np.array([e["x"][0] for e in truth]),
        r=np.array([e["x"][1] for e in truth]),
        description=description,
    )


def _columns(d: DriveTable) -> dict[str, np.ndarray]:
    if d.yaw_t:
        raise ValueError("a CSV or Parquet table has one time column: the sensors' own stamps need MDF4 or a bag")
    cols = {"t": d.t, "speed": d.speed, "steering": d.steering, **{f"yaw{i}": v for i, v in d.yaw.items()}}
    if d.beta is not None and d.r is not None:
        cols |= {"beta_ref": d.beta, "r_ref": d.r}
    return cols


def write_log(d: DriveTable, path: Path, fmt: str) -> Path:
    """Write ``d`` as ``fmt`` (one of :data:`WRITE_FORMATS`) at ``path``; returns the log's path (a bag: its directory)."""
    if fmt == "csv":
        import csv

        cols = _columns(d)
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            w.writerows(zip(*(map(repr, map(float, c)) for c in cols.values())))
        return path
    if fmt == "parquet":
        require("pyarrow", "writing a Parquet drive log", extra="logs")
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table(_columns(d)).replace_schema_metadata({"description": d.description})
        pq.write_table(table, path)
        return path
    if fmt == "mdf4":
        return _write_mdf4(d, path)
    if fmt in ("rosbag-mcap", "rosbag-sqlite3"):
        return _write_bag(d, path, fmt.split("-")[1])
    raise ValueError(f"unknown log format {fmt!r} (one of {', '.join(WRITE_FORMATS)})")


def _write_mdf4(d: DriveTable, path: Path) -> Path:
    require("asammdf", "writing an MDF4 drive log")
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    mdf.header.comment = d.description
    common = [Signal(d.speed, d.t, name="speed", unit="m/s"), Signal(d.steering, d.t, name="steering", unit="rad")]
    if d.beta is not None and d.r is not None:
        common += [Signal(d.beta, d.t, name="beta_ref", unit="rad"), Signal(d.r, d.t, name="r_ref", unit="rad/s")]
    mdf.append(common, comment="vehicle")
    for i, v in d.yaw.items():  # a group per sensor: each its own time base
        mdf.append([Signal(v, d.stamps(i), name=f"yaw{i}", unit="rad/s")], comment=f"yaw-rate sensor {i}")
    mdf.save(path, overwrite=True)
    mdf.close()
    return path


def _write_bag(d: DriveTable, path: Path, storage: str) -> Path:
    """The bag, its messages generated topic by topic and merged in time (never held all at once: a 30-minute drive
    at 100 Hz is millions of messages)."""
    require("rosbags", "writing a ROS 2 bag")
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Imu, Odom, F64, V3S = T["sensor_msgs/msg/Imu"], T["nav_msgs/msg/Odometry"], T["std_msgs/msg/Float64"], T["geometry_msgs/msg/Vector3Stamped"]
    Header, Time, V3, Q = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"], T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    Twist, TwistCov, Pose, PoseCov, Point = (
        T["geometry_msgs/msg/Twist"],
        T["geometry_msgs/msg/TwistWithCovariance"],
        T["geometry_msgs/msg/Pose"],
        T["geometry_msgs/msg/PoseWithCovariance"],
        T["geometry_msgs/msg/Point"],
    )
    zero3, cov9, cov36 = V3(x=0.0, y=0.0, z=0.0), np.zeros(9), np.zeros(36)
    pose = Pose(position=Point(x=0.0, y=0.0, z=0.0), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0))

    def header(ns: int, frame: str) -> Any:
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame)

    def odom(ns: int, v: float) -> Any:
        twist = Twist(linear=V3(x=v, y=0.0, z=0.0), angular=zero3)
        return Odom(
            header=header(ns, "odom"), child_frame_id="base_link", pose=PoseCov(pose=pose, covariance=cov36), twist=TwistCov(twist=twist, covariance=cov36)
        )

    def imu(ns: int, i: int, v: float) -> Any:
        return Imu(
            header=header(ns, f"imu{i}"),
            orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=cov9,
            angular_velocity=V3(x=0.0, y=0.0, z=v),
            angular_velocity_covariance=cov9,
            linear_acceleration=zero3,
            linear_acceleration_covariance=cov9,
        )

    t_ns = np.round(d.t * 1e9).astype(np.int64).tolist()
    topics: list[tuple[str, str, Iterator[tuple[int, object]]]] = [
        (SPEED_TOPIC, Odom.__msgtype__, (((ns, odom(ns, float(v))) for ns, v in zip(t_ns, d.speed.tolist())))),
        (STEERING_TOPIC, F64.__msgtype__, (((ns, F64(data=v)) for ns, v in zip(t_ns, d.steering.tolist())))),
    ]
    if d.beta is not None and d.r is not None:
        if d.ins_message:  # one INS topic: β in vector.x, r in vector.z, header-stamped
            ins = ((ns, V3S(header=header(ns, "ins"), vector=V3(x=b, y=0.0, z=r))) for ns, b, r in zip(t_ns, d.beta.tolist(), d.r.tolist()))
            topics.append((INS_TOPIC, V3S.__msgtype__, ins))
        else:
            topics.append((BETA_TOPIC, F64.__msgtype__, ((ns, F64(data=v)) for ns, v in zip(t_ns, d.beta.tolist()))))
            topics.append((R_TOPIC, F64.__msgtype__, ((ns, F64(data=v)) for ns, v in zip(t_ns, d.r.tolist()))))
    for i, v in d.yaw.items():
        stamps = np.round(d.stamps(i) * 1e9).astype(np.int64).tolist()
        topics.append((imu_topic(i), Imu.__msgtype__, ((ns, imu(ns, i, val)) for ns, val in zip(stamps, v.tolist(), strict=True))))

    def tagged(n: int, it: Iterator[tuple[int, object]]) -> Iterator[tuple[int, int, object]]:
        return ((ns, n, msg) for ns, msg in it)

    if path.exists():
        shutil.rmtree(path)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        conns = [w.add_connection(topic, mtype, typestore=ts) for topic, mtype, _ in topics]
        # a bag is written in arrival order: the topics merged by stamp (a stable merge, topic order on ties)
        for ns, n, msg in heapq.merge(*(tagged(n, it) for n, (_, _, it) in enumerate(topics)), key=lambda m: (m[0], m[1])):
            w.write(conns[n], ns, ts.serialize_cdr(msg, topics[n][1]))
    if d.description:
        (path / "README.txt").write_text(d.description + "\n")
    return path


def mapping_toml(
    d: DriveTable, fmt: str, accuracy: tuple[float, float] | None, gap_tolerance_s: float | None = None, note: str = "", start_s: float | None = None
) -> str:
    """The mapping of a log ``write_log`` wrote (units as written: SI; ``accuracy``: the reference's, None: no reference;
    ``start_s``: step 0's log time, None: the default)."""
    bag = fmt.startswith("rosbag")
    out = [f"# {note}" if note else "# the mapping of a drive log written by netsetest (logs/write.py)", "[log]"]
    out.append(f'format = "{"rosbag" if bag else fmt}"')
    if gap_tolerance_s is not None:
        out.append(f"gap_tolerance_s = {float(gap_tolerance_s)!r}")
    if start_s is not None:
        out.append(f"start_s = {float(start_s)!r}")
    if bag:
        out += ["", "[speed]", f'channel = "{SPEED_TOPIC}"', 'field = "twist.twist.linear.x"', 'unit = "m/s"']
        out += ["", "[steering]", f'channel = "{STEERING_TOPIC}"', 'unit = "rad"']
    else:
        out += ["", "[speed]", 'channel = "speed"', 'unit = "m/s"', "", "[steering]", 'channel = "steering"', 'unit = "rad"']
    for i in d.yaw:
        out += ["", "[[yaw_rate]]", f"node = {i}"]
        out += [f'channel = "{imu_topic(i)}"', 'field = "angular_velocity.z"'] if bag else [f'channel = "yaw{i}"']
        out.append('unit = "rad/s"')
    if accuracy is not None and d.beta is not None:
        b, r = (BETA_TOPIC, R_TOPIC) if bag else ("beta_ref", "r_ref")
        fb, fr = ("", "")
        if bag and d.ins_message:
            b, r, fb, fr = INS_TOPIC, INS_TOPIC, ', field = "vector.x"', ', field = "vector.z"'
        out += ["", "[reference]", f'beta = {{ channel = "{b}"{fb}, unit = "rad" }}', f'r = {{ channel = "{r}"{fr}, unit = "rad/s" }}']
        out.append(f"accuracy = {{ beta = {float(accuracy[0])!r}, r = {float(accuracy[1])!r} }}")
    return "\n".join(out) + "\n"


def log_path(directory: Path, stem: str, fmt: str) -> Path:
    return directory / (stem + ("_" + fmt.split("-")[1] if fmt.startswith("rosbag") else "") + SUFFIX[fmt])


__all__ = ["SUFFIX", "WRITE_FORMATS", "DriveTable", "from_truth", "imu_topic", "log_path", "mapping_toml", "write_log"]
