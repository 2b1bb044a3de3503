"""Turn a bare .mcap into a rosbag2 bag directory (the .mcap plus the metadata.yaml rosbag2 writes).

``ros2 bag`` (Iron and later) and Foxglove open a bare .mcap, but the ``rosbags`` library's rosbag2
Reader (0.11) only opens a directory with a metadata.yaml. This writes the file rosbag2 itself would
write (metadata version 9, Jazzy): storage "mcap", start time and duration, message count per topic
with type, "cdr" and the offered QoS profiles, the relative file path. type_description_hash is left
out: it is optional and readers check it only when present.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.io.mcap.scan import McapScan


def _indent(text: str, spaces: int) -> str:
    return "\n".join(" " * spaces + line for line in text.splitlines())


def bag_metadata_yaml(mcap_path: Path, relative_name: str) -> str:
    """metadata.yaml text for one .mcap storage file."""
    scan = McapScan(mcap_path)
    counts = scan.message_counts()
    start, end = scan.time_range()
    total = sum(counts.values())
    topics = []
    for info in scan.topics.values():
        qos = info.metadata.get("offered_qos_profiles", "")
        qos_yaml = ("\n" + _indent(qos, 10)) if qos.strip() else ' ""'
        topics.append(
            f"    - topic_metadata:\n        name: {info.topic}\n        type: {info.type_name}\n"
            f"        serialization_format: {info.message_encoding}\n        offered_qos_profiles:{qos_yaml}\n"
            f"      message_count: {counts.get(info.topic, 0)}"
        )
    period = f"  starting_time:\n    nanoseconds_since_epoch: {start}\n  duration:\n    nanoseconds: {end - start}\n"
    return (
        "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n"
        f"  duration:\n    nanoseconds: {end - start}\n  starting_time:\n    nanoseconds_since_epoch: {start}\n"
        f"  message_count: {total}\n  topics_with_message_count:\n" + "\n".join(topics) + "\n"
        '  compression_format: ""\n  compression_mode: ""\n'
        f"  relative_file_paths:\n    - {relative_name}\n"
        f"  files:\n    - path: {relative_name}\n"
        + _indent(period, 4)
        + f"\n      message_count: {total}\n"
        "  custom_data: ~\n  ros_distro: gtsam_dvl\n"
    )


def make_bag_dir(
    mcap_path: str | os.PathLike[str], folder: str | os.PathLike[str] | None = None
) -> Path:
    """Create ``folder`` (default: the .mcap's name without suffix) holding the .mcap (hard link, or a
    copy across file systems) and its metadata.yaml. Returns the folder."""
    src = Path(mcap_path)
    out = Path(folder) if folder is not None else src.with_suffix("")
    if out.exists():
        raise GtsamDvlError(f"{out}: exists already; choose another bag folder")
    out.mkdir(parents=True)
    target = out / src.name
    try:
        os.link(src, target)
    except OSError:
        shutil.copyfile(src, target)
    (out / "metadata.yaml").write_text(bag_metadata_yaml(src, src.name))
    return out
