"""The schema version of what gtsam_dvl writes (configurations and results) and the one migration table that
brings a configuration written by an older version to this one.

A written configuration (to_toml, a result's config.json) carries ``schema_version = SCHEMA_VERSION``; a result
carries it in its "gtsam_dvl_result" metadata record and config.json. MIGRATIONS lists, in order, each version
and what changed in it, with the function that turns a configuration dict of the version before into one of
this version: the keys it added, set as the runs that wrote the older file behaved. A file without
schema_version was written before it existed, or by a user: a whole written configuration (its [dvl] lists
DUMP_KEYS, which only a written one does) is as old as the first key it lacks among those the table added
(``detected_version``); a user's partial file is current (the keys it leaves out take their defaults).
``migrated`` then applies every later step in order. A schema_version newer than SCHEMA_VERSION is refused with
one line.

A result's summary (core/summary.py) is migrated by its own steps (SUMMARY_MIGRATIONS), keyed by these versions:
version 8 changed the summary alone.

Adding a key whose default changes what an older file's runs did: append a Migration (version + 1, the key,
what the runs that wrote such files did) and raise SCHEMA_VERSION; a test loads a file of each older version.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from gtsam_dvl.core.errors import GtsamDvlError

Table = dict[str, Any]

# keys of [dvl] that only a whole written configuration (a result's config.json, to_toml) lists, not a user's
DUMP_KEYS = {"time_offset_window_s", "jump_margin_m_s", "motion_dv_m_s", "accel_imu_factor"}


def _with_key(data: Table, section: str, key: str, value: Any) -> Table:
    """data with [section] key = value where the section is a table without the key."""
    table = data.get(section)
    if not isinstance(table, dict) or key in table:
        return data
    return {**data, section: {**table, key: value}}


def _white_dvl(data: Table) -> Table:
    """Runs before [dvl] correlated_sigma_m_s took the DVL's error as white (a sensor preset's value stays)."""
    dvl = data.get("dvl")
    if isinstance(dvl, dict) and dvl.get("model") is not None:
        return data
    return _with_key(data, "dvl", "correlated_sigma_m_s", 0.0)


def _water_track_refused(data: Table) -> Table:
    """Runs before [current] refused water-track pings."""
    return data if "current" in data else {**data, "current": {"water_track": "refuse"}}


@dataclass(frozen=True)
class Migration:
    """One step of the table: a configuration of version - 1 -> one of version. added: the [section] key the
    version added (its absence marks a whole written configuration as older; None: nothing added)."""

    version: int
    change: str
    migrate: Callable[[Table], Table]
    added: tuple[str, str] | None = None

    def lacks(self, data: Table) -> bool:
        """data (a whole written configuration) predates this version: it lacks the key the version added."""
        if self.added is None:
            return False
        section, key = self.added
        if key == "":
            return section not in data
        table = data.get(section)
        return isinstance(table, dict) and key not in table


MIGRATIONS: tuple[Migration, ...] = (
    Migration(
        2,
        "[dvl] correlated_sigma_m_s: the DVL's correlated error (earlier runs: white)",
        _white_dvl,
        ("dvl", "correlated_sigma_m_s"),
    ),
    Migration(
        3,
        "[current]: water-track pings and the water current (earlier runs refused the pings)",
        _water_track_refused,
        ("current", ""),
    ),
    Migration(
        4,
        "[priors] hold_weak_information (earlier runs estimated every calibration direction: 0)",
        lambda d: _with_key(d, "priors", "hold_weak_information", 0.0),
        ("priors", "hold_weak_information"),
    ),
    Migration(
        5,
        "[priors] nominal_check (earlier runs did not check the nominal calibration: false)",
        lambda d: _with_key(d, "priors", "nominal_check", False),
        ("priors", "nominal_check"),
    ),
    Migration(
        6,
        "[dvl] constant_error_sigma_m_s (earlier runs gave a constant DVL error no share: 0)",
        lambda d: _with_key(d, "dvl", "constant_error_sigma_m_s", 0.0),
        ("dvl", "constant_error_sigma_m_s"),
    ),
    Migration(7, "schema_version written in configurations and results", lambda d: d),
    # the configuration is unchanged; a summary's step is core/summary.py SUMMARY_MIGRATIONS
    Migration(
        8,
        "the summary: one typed model (core/summary.py), its schema_version written, calibration_hold one shape "
        "(reason, why, held directions as objects: the EKF's held names become directions)",
        lambda d: d,
    ),
)
SCHEMA_VERSION = MIGRATIONS[-1].version
# the last version whose configurations and results were written without schema_version (written since 7)
UNVERSIONED = 6


def is_written_whole(data: Any) -> bool:
    """data is a whole configuration as gtsam_dvl writes it (its [dvl] lists DUMP_KEYS), not a user's."""
    dvl = data.get("dvl") if isinstance(data, dict) else None
    return isinstance(dvl, dict) and DUMP_KEYS <= set(dvl)


def detected_version(data: Any) -> int:
    """The version of a configuration without schema_version: a whole written one is as old as the first key it
    lacks among those MIGRATIONS added (the version before that key; UNVERSIONED, the last version without
    schema_version, when it lacks none); a user's is SCHEMA_VERSION."""
    if not is_written_whole(data):
        return SCHEMA_VERSION
    for step in MIGRATIONS:
        if step.lacks(data):
            return step.version - 1
    return UNVERSIONED


def checked_version(value: Any, source: str) -> int:
    """A schema_version as written, checked: an integer from 1 to SCHEMA_VERSION, else one GtsamDvlError line."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise GtsamDvlError(
            f"{source}: schema_version must be an integer from 1 to {SCHEMA_VERSION}, got {value!r}"
        )
    if value > SCHEMA_VERSION:
        raise GtsamDvlError(
            f"{source}: schema_version {value} is newer than this gtsam_dvl reads (at most {SCHEMA_VERSION}): "
            "written by a newer version; upgrade gtsam_dvl to read it"
        )
    return value


def migrated(data: Any, source: str, detect: bool = True) -> Any:
    """A configuration dict brought to SCHEMA_VERSION, its schema_version key taken out: from the version it
    states (checked_version), else (detect) the one detected_version finds, else as it is (no migration)."""
    if not isinstance(data, dict):
        return data
    if "schema_version" in data:
        version = checked_version(data["schema_version"], source)
        data = {k: v for k, v in data.items() if k != "schema_version"}
    elif detect:
        version = detected_version(data)
    else:
        return data
    for step in MIGRATIONS:
        if step.version > version:
            data = step.migrate(data)
    return data
