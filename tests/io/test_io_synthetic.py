"""The synthetic log of the I/O tests (tests/support/synthetic_log.py), and checks of the message definitions and
CDR layouts every other I/O test relies on."""

from __future__ import annotations

import numpy as np
from mcap_ros2._dynamic import serialize_dynamic

from gtsam_dvl.io.ros2 import cdr
from gtsam_dvl.io.ros2.msgdefs import SEPARATOR, MsgField, fields, full_definition
from tests.support.synthetic_log import make_log


def test_synthetic_log_is_consistent() -> None:
    log = make_log(10.0)
    assert (
        len(log.imu) == 1000
        and len(log.dvl) == 10
        and log.truth is not None
        and len(log.truth) == 100
    )
    assert np.all(np.isnan(log.dvl.d_v[~log.dvl.valid]))


def test_full_definition_is_concatenated_as_rosbag2_does() -> None:
    text = full_definition("nav_msgs/msg/Odometry")
    parts = text.split(SEPARATOR + "\n")
    assert "std_msgs/Header header" in parts[0] and "MSG:" not in parts[0]
    names = [p.splitlines()[0] for p in parts[1:]]
    assert all(n.startswith("MSG: ") for n in names)
    assert len(names) == len(set(names))
    assert {
        "MSG: std_msgs/msg/Header",
        "MSG: builtin_interfaces/msg/Time",
        "MSG: geometry_msgs/msg/Pose",
        "MSG: geometry_msgs/msg/Quaternion",
        "MSG: geometry_msgs/msg/TwistWithCovariance",
    } <= set(names)
    dvl = full_definition("marine_acoustic_msgs/msg/Dvl")
    assert (
        "BSD 3-Clause License" in dvl
        and "University of Washington Applied Physics Laboratory" in dvl
    )
    assert "apl-ocean-engineering/marine_msgs" in dvl


def test_message_fields_are_read_from_the_definitions() -> None:
    """Constants are left out, arrays keep their size, sequences have none, short type names are qualified."""
    fix = fields("sensor_msgs/msg/NavSatFix")
    assert [f.name for f in fix] == [
        "header",
        "status",
        "latitude",
        "longitude",
        "altitude",
        "position_covariance",
        "position_covariance_type",
    ]
    assert fix[1] == MsgField("sensor_msgs/msg/NavSatStatus", "status", 1)
    assert fix[5] == MsgField("float64", "position_covariance", 9)
    assert fields("nav_msgs/msg/Path")[1] == MsgField(
        "geometry_msgs/msg/PoseStamped", "poses", None
    )
    assert MsgField("geometry_msgs/msg/Vector3", "beam_unit_vec", 4) in fields(
        "marine_acoustic_msgs/msg/Dvl"
    )
    names = [f.name for f in cdr.SPECS["nav_msgs/msg/Odometry"]]
    assert names == [
        "sec",
        "nanosec",
        "frame_id",
        "child_frame_id",
        "position",
        "orientation",
        "pose_covariance",
        "linear",
        "angular",
        "twist_covariance",
    ]
    assert cdr.Field("beam_unit_vec", "f8", 12) in cdr.DVL


def test_layouts_match_an_independent_cdr_encoder() -> None:
    """Our structured-array bytes equal what mcap_ros2's generic encoder produces from the definition."""
    rng = np.random.default_rng(1)
    for type_name, spec in cdr.SPECS.items():
        strings = {f.name: "frame_" * (1 + i) for i, f in enumerate(spec) if f.code == "str"}
        arr = cdr.new_messages(spec, strings, 1)
        values: dict[str, object] = {}
        for f in spec:
            if f.code == "str":
                continue
            v = (
                rng.integers(0, 200, f.count)
                if f.code in ("u1", "i4", "u4", "u2")
                else rng.integers(-1, 3, f.count)
                if f.code == "i1"
                else rng.random(f.count) > 0.5
                if f.code == "?"
                else rng.normal(size=f.count)
            )
            arr[f.name] = v if f.count > 1 else v[0]
            values[f.name] = arr[f.name][0]
        body = arr.tobytes()
        encoder = serialize_dynamic(type_name, full_definition(type_name))[type_name]
        msg = _nested(type_name, values, strings)
        assert encoder(msg) == body, type_name


def _nested(type_name: str, v: dict, s: dict) -> dict:
    """The dict form mcap_ros2's encoder takes, for the flattened fields of cdr.SPECS."""

    def vec(a: object) -> dict:
        return dict(zip("xyz", np.asarray(a).tolist(), strict=True))

    def quat(a: object) -> dict:
        return dict(zip("xyzw", np.asarray(a).tolist(), strict=True))

    out: dict = {
        "header": {
            "stamp": {"sec": int(v["sec"]), "nanosec": int(v["nanosec"])},
            "frame_id": s["frame_id"],
        }
    }
    if type_name == "sensor_msgs/msg/Imu":
        out.update(
            orientation=quat(v["orientation"]),
            angular_velocity=vec(v["angular_velocity"]),
            linear_acceleration=vec(v["linear_acceleration"]),
        )
        out.update({k: np.asarray(v[k]).tolist() for k in v if k.endswith("covariance")})
    elif type_name == "geometry_msgs/msg/TwistStamped":
        out["twist"] = {"linear": vec(v["linear"]), "angular": vec(v["angular"])}
    elif type_name == "geometry_msgs/msg/TwistWithCovarianceStamped":
        out["twist"] = {
            "twist": {"linear": vec(v["linear"]), "angular": vec(v["angular"])},
            "covariance": np.asarray(v["covariance"]).tolist(),
        }
    elif type_name == "geometry_msgs/msg/AccelWithCovarianceStamped":
        out["accel"] = {
            "accel": {"linear": vec(v["linear"]), "angular": vec(v["angular"])},
            "covariance": np.asarray(v["covariance"]).tolist(),
        }
    elif type_name == "geometry_msgs/msg/PoseWithCovarianceStamped":
        out["pose"] = {
            "pose": {"position": vec(v["position"]), "orientation": quat(v["orientation"])},
            "covariance": np.asarray(v["covariance"]).tolist(),
        }
    elif type_name == "geometry_msgs/msg/Vector3Stamped":
        out["vector"] = vec(v["vector"])
    elif type_name == "sensor_msgs/msg/Temperature":
        out.update(temperature=float(v["temperature"]), variance=float(v["variance"]))
    elif type_name == "sensor_msgs/msg/FluidPressure":
        out.update(fluid_pressure=float(v["fluid_pressure"]), variance=float(v["variance"]))
    elif type_name == "nav_msgs/msg/Odometry":
        out["child_frame_id"] = s["child_frame_id"]
        out["pose"] = {
            "pose": {"position": vec(v["position"]), "orientation": quat(v["orientation"])},
            "covariance": np.asarray(v["pose_covariance"]).tolist(),
        }
        out["twist"] = {
            "twist": {"linear": vec(v["linear"]), "angular": vec(v["angular"])},
            "covariance": np.asarray(v["twist_covariance"]).tolist(),
        }
    elif type_name == "sensor_msgs/msg/NavSatFix":
        out["status"] = {"status": int(v["status"]), "service": int(v["service"])}
        out.update(
            latitude=float(v["latitude"]),
            longitude=float(v["longitude"]),
            altitude=float(v["altitude"]),
            position_covariance=np.asarray(v["position_covariance"]).tolist(),
            position_covariance_type=int(v["position_covariance_type"]),
        )
    elif type_name == "marine_acoustic_msgs/msg/Dvl":
        out.update(
            {
                k: (np.asarray(v[k]).tolist() if np.ndim(v[k]) else np.asarray(v[k]).item())
                for k in v
                if k not in ("sec", "nanosec", "velocity", "beam_unit_vec")
            }
        )
        out["velocity"] = vec(v["velocity"])
        out["beam_unit_vec"] = [vec(r) for r in np.asarray(v["beam_unit_vec"]).reshape(4, 3)]
    else:
        raise AssertionError(type_name)
    return out
