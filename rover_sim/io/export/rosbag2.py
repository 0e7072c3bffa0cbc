"""ROS 2 bag (MCAP storage) written with ``rosbags``: no ROS installation needed, ``ros2 bag play`` reads it.

``OUT/rosbag2/`` (``metadata.yaml`` + ``rosbag2_0.mcap``), message types of ROS 2 Humble:

==================================  ==========================  ==================================================
topic                               type                        content
==================================  ==========================  ==================================================
/<camera>/left/image_rect           sensor_msgs/Image           rectified greyscale (mono8), frame <camera>_left
/<camera>/left/camera_info          sensor_msgs/CameraInfo      K, P; D = 0 (rectified)
/<camera>/right/image_rect, ...     (the same for the right)    P[3] = -fx * baseline (ROS stereo convention)
/imu/data                           sensor_msgs/Imu             gyro, accel in frame ``rover``; no orientation
/joint_states                       sensor_msgs/JointState      wheel spin, steering, commanded mast pan/elevation
/odom/dead_reckoning                nav_msgs/Odometry           onboard wheel/IMU dead reckoning (estimate)
/odom/vo                            nav_msgs/Odometry           onboard VO-corrected pose (estimate; VO runs only)
/tf                                 tf2_msgs/TFMessage          ground truth ``world`` -> ``rover`` (8 Hz)
/tf_static                          tf2_msgs/TFMessage          ``rover`` -> camera optical frames (latched;
                                                                republished if the mast moves the navcam): the
                                                                true rectified cameras the images are in
==================================  ==========================  ==================================================

Stamps are simulation time (header stamp = bag receive time). The odometry carries each estimate's own stamp (the
encoder reading it was updated with), one message per update; its twist is left zero.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nav.geometry import R_to_quat_wxyz
from nav.trajectory import Pose
from nav.types import EncoderSample, ImuSample
from rover_sim.io.export.base import MAST_JOINTS, STEER_JOINTS, WHEEL_JOINTS, DatasetWriter, ExportMeta, Frame, t_ns

WORLD, ROVER = "world", "rover"
SIDES = ("left", "right")
TF_STATIC_TOLERANCE = 1e-3  # republish /tf_static when a camera mounting moves by more than this (m; rad): a
# re-pointed mast, not the servo sag of a few 1e-4 rad while driving


class Rosbag2Writer(DatasetWriter):
    name = "rosbag2"

    def __init__(self, out: Path) -> None:
        from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(out)
        if self.path.exists() and not any(self.path.iterdir()):
            self.path.rmdir()  # rosbags creates the bag directory itself
        self.store = get_typestore(Stores.ROS2_HUMBLE)
        self.t = self.store.types
        self.bag = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.bag.open()
        zero = QosTime(0, 0)
        self.latched = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, zero,
                           zero, QosLiveliness.AUTOMATIC, zero, False)  # fmt: skip
        self.conns: dict[str, object] = {}
        self.camera = "camera"
        self.static_T: list[np.ndarray] | None = None
        self.counts: dict[str, int] = {}

    # ------------------------------------------------------------------ plumbing
    def conn(self, topic: str, msgtype: str, latched: bool = False):  # noqa: ANN201
        c = self.conns.get(topic)
        if c is None:
            qos = (self.latched,) if latched else ()
            c = self.bag.add_connection(topic, msgtype, typestore=self.store, offered_qos_profiles=qos)
            self.conns[topic] = c
        return c

    def put(self, topic: str, msg, t_s: float, latched: bool = False) -> None:  # noqa: ANN001
        c = self.conn(topic, msg.__msgtype__, latched)
        self.bag.write(c, t_ns(t_s), self.store.serialize_cdr(msg, msg.__msgtype__))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def header(self, t_s: float, frame_id: str):  # noqa: ANN201
        ns = t_ns(t_s)
        return self.t["std_msgs/msg/Header"](self.t["builtin_interfaces/msg/Time"](ns // 10**9, ns % 10**9), frame_id)

    def vec3(self, v):  # noqa: ANN001, ANN201
        return self.t["geometry_msgs/msg/Vector3"](float(v[0]), float(v[1]), float(v[2]))

    def quat(self, q_wxyz):  # noqa: ANN001, ANN201
        w, x, y, z = (float(a) for a in q_wxyz)
        return self.t["geometry_msgs/msg/Quaternion"](x, y, z, w)

    def transform(self, t_s: float, parent: str, child: str, T: np.ndarray):  # noqa: ANN201
        tf = self.t["geometry_msgs/msg/Transform"](self.vec3(T[:3, 3]), self.quat(R_to_quat_wxyz(T[:3, :3])))
        return self.t["geometry_msgs/msg/TransformStamped"](self.header(t_s, parent), child, tf)

    # ------------------------------------------------------------------ streams
    def start(self, meta: ExportMeta) -> None:
        self.camera = meta.camera

    def frame(self, frame: Frame) -> None:
        cam, rig = frame.camera, frame.rig
        static = [frame.T_rover_cam, frame.T_rover_right_cam]
        if self.mounting_changed(static):
            self.static_T = static
            tfs = [self.transform(frame.t_s, ROVER, f"{cam}_{side}", T) for side, T in zip(SIDES, static, strict=True)]
            self.put("/tf_static", self.t["tf2_msgs/msg/TFMessage"](tfs), frame.t_s, latched=True)
        K = rig.left.K
        for side, image, tx in (("left", frame.left_u8, 0.0), ("right", frame.right_u8, -K[0, 0] * rig.baseline_m)):
            h, w = image.shape
            hdr = self.header(frame.t_s, f"{cam}_{side}")
            img = self.t["sensor_msgs/msg/Image"](hdr, h, w, "mono8", 0, w, np.ascontiguousarray(image).ravel())
            self.put(f"/{cam}/{side}/image_rect", img, frame.t_s)
            P = np.hstack([K, [[tx], [0.0], [0.0]]])
            roi = self.t["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
            info = self.t["sensor_msgs/msg/CameraInfo"](
                hdr, h, w, "plumb_bob", np.zeros(5), K.ravel().astype(float), np.eye(3).ravel(), P.ravel(), 0, 0, roi
            )
            self.put(f"/{cam}/{side}/camera_info", info, frame.t_s)

    def mounting_changed(self, static: list[np.ndarray]) -> bool:
        if self.static_T is None:
            return True
        return max(float(np.abs(a - b).max()) for a, b in zip(static, self.static_T, strict=True)) > TF_STATIC_TOLERANCE

    def imu(self, sample: ImuSample) -> None:
        cov = np.zeros(9)
        no_orientation = np.zeros(9)
        no_orientation[0] = -1.0  # REP 145: orientation not provided
        msg = self.t["sensor_msgs/msg/Imu"](
            self.header(sample.t_s, ROVER), self.quat((1.0, 0.0, 0.0, 0.0)), no_orientation,
            self.vec3(sample.gyro_rad_s), cov, self.vec3(sample.accel_m_s2), cov,
        )  # fmt: skip
        self.put("/imu/data", msg, sample.t_s)

    def encoders(self, sample: EncoderSample, mast_pan_rad: float, mast_elevation_rad: float) -> None:
        names = list(WHEEL_JOINTS + STEER_JOINTS + MAST_JOINTS)
        pos = np.concatenate([sample.wheel_angle_rad, sample.steer_angle_rad, [mast_pan_rad, mast_elevation_rad]])
        msg = self.t["sensor_msgs/msg/JointState"](
            self.header(sample.t_s, ROVER), names, pos.astype(float), np.zeros(0), np.zeros(0)
        )
        self.put("/joint_states", msg, sample.t_s)

    def truth(self, pose: Pose) -> None:
        tf = self.transform(pose.t_s, WORLD, ROVER, pose.as_matrix())
        self.put("/tf", self.t["tf2_msgs/msg/TFMessage"]([tf]), pose.t_s)

    def odometry(self, topic: str, t_s: float, pose: Pose) -> None:
        T = self.t
        p = T["geometry_msgs/msg/Pose"](T["geometry_msgs/msg/Point"](*map(float, pose.position_xyz_m)),
                                        self.quat(pose.quat_wxyz))  # fmt: skip
        twist = T["geometry_msgs/msg/Twist"](self.vec3(np.zeros(3)), self.vec3(np.zeros(3)))
        msg = T["nav_msgs/msg/Odometry"](
            self.header(t_s, WORLD),
            ROVER,
            T["geometry_msgs/msg/PoseWithCovariance"](p, np.zeros(36)),
            T["geometry_msgs/msg/TwistWithCovariance"](twist, np.zeros(36)),
        )
        self.put(topic, msg, t_s)

    def estimate(self, source: str, pose: Pose) -> None:
        self.odometry(f"/odom/{source}", pose.t_s, pose)

    def close(self) -> None:
        self.bag.close()
