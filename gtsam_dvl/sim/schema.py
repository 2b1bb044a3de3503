"""Validation of scenario dicts: every bad, missing or unknown key becomes one GtsamDvlError line that
names the file and the key. Kept apart from scenario.py so that file stays a readable list of dataclasses.

Segment kinds (keys in brackets are optional; the vehicle keeps its attitude unless a kind changes it):

- static: duration_s. The vehicle must be at rest.
- level: duration_s, [speed_end_m_s], [speed_bump_m_s]. Constant attitude and depth; the horizontal speed
  blends smoothly to speed_end and/or gets a smooth surge of peak speed_bump (paper Type I).
- straight: duration_s. Constant velocity and attitude.
- descent / ascent: duration_s, peak_vertical_speed_m_s. Ballast: constant attitude and horizontal
  speed, the vertical speed rises smoothly to the peak and back to zero (paper Type I).
- turn: duration_s, heading_change_deg (positive left), [bank_deg]. Constant speed (paper Type II).
- arc: duration_s, turn_rate_deg_s (positive left). A steady turn: constant speed and attitude but the yaw, the
  turn rate constant from the segment's start to its end (held before t = 0 when it is the first segment, after
  the end when the last: sim/motion.py). Paper Type II.
- square: leg_duration_s, turn_duration_s, [bank_deg], [direction = "left"], [sides = 4],
  [turn_first = false]: legs and turns of 360/sides deg alternating, leg first unless turn_first (the
  paper's "I and II" segment).
"""

from __future__ import annotations

from typing import Any

from gtsam_dvl.core.errors import GtsamDvlError

SEGMENT_KEYS: dict[str, tuple[str, ...]] = {
    "static": ("duration_s",),
    "level": ("duration_s", "speed_end_m_s", "speed_bump_m_s"),
    "straight": ("duration_s",),
    "descent": ("duration_s", "peak_vertical_speed_m_s"),
    "ascent": ("duration_s", "peak_vertical_speed_m_s"),
    "turn": ("duration_s", "heading_change_deg", "bank_deg"),
    "arc": ("duration_s", "turn_rate_deg_s"),
    "square": ("leg_duration_s", "turn_duration_s", "bank_deg", "direction", "sides", "turn_first"),
}
SEGMENT_KINDS = tuple(SEGMENT_KEYS)
# the keys a segment may leave out (in brackets in the module doc) in every kind that takes them; it needs the others
_OPTIONAL_KEYS = frozenset(
    ("speed_end_m_s", "speed_bump_m_s", "bank_deg", "direction", "sides", "turn_first")
)


class Reader:
    """Typed access to a scenario dict; errors name the source file and the dotted key."""

    def __init__(self, raw: dict[str, Any], source: str) -> None:
        self.raw = raw
        self.source = source

    def fail(self, key: str, message: str) -> GtsamDvlError:
        return GtsamDvlError(f"{self.source}: key '{key}': {message}")

    def require(self, ok: bool, key: str, message: str) -> None:
        if not ok:
            raise self.fail(key, message)

    def check_keys(
        self, prefix: str, allowed: list[str] | tuple[str, ...], d: dict[str, Any] | None = None
    ) -> None:
        d = self.raw if d is None else d
        for key in d:
            if key not in allowed:
                full = f"{prefix}.{key}" if prefix else key
                raise self.fail(full, f"unknown key (allowed: {', '.join(allowed)})")

    def number(self, key: str, value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"expected a number, got {value!r}")
        return float(value)

    def vector(self, key: str, value: Any) -> tuple[float, float, float]:
        if not isinstance(value, list) or len(value) != 3:
            raise self.fail(key, f"expected a list of 3 numbers, got {value!r}")
        x, y, z = (self.number(key, v) for v in value)
        return (x, y, z)

    def scalar_or_vector(self, key: str, value: Any) -> float | tuple[float, float, float]:
        """A number, or a list of 3 (one per axis)."""
        return self.vector(key, value) if isinstance(value, list) else self.number(key, value)

    def table(
        self,
        name: str,
        defaults: dict[str, Any],
        vectors: tuple[str, ...] = (),
        strings: tuple[str, ...] = (),
        per_axis: tuple[str, ...] = (),
    ) -> dict[str, Any]:
        """Values of table `name`: defaults filled in, None defaults (except vectors) required. per_axis: keys that
        take a number or a list of 3."""
        d = self.raw.get(name, {})
        if not isinstance(d, dict):
            raise self.fail(name, "expected a table")
        self.check_keys(name, list(defaults), d)
        out: dict[str, Any] = {}
        for key, default in defaults.items():
            full = f"{name}.{key}"
            if key not in d:
                if default is None and key not in vectors:
                    raise self.fail(full, "missing")
                out[key] = default
            elif key in vectors:
                out[key] = self.vector(full, d[key])
            elif key in per_axis:
                out[key] = self.scalar_or_vector(full, d[key])
            elif key in strings:
                if not isinstance(d[key], str):
                    raise self.fail(full, f"expected a string, got {d[key]!r}")
                out[key] = d[key]
            else:
                out[key] = self.number(full, d[key])
        return out


# the paper's motion type of each segment kind; a level segment's depends on its speeds (_paper_type)
_PAPER_TYPE = {
    "static": "-",
    "straight": "-",
    "descent": "I",
    "ascent": "I",
    "turn": "II",
    "arc": "II",
    "square": "I+II",
}


def parse_segments(r: Reader, speed0_m_s: float) -> list[dict[str, Any]]:
    """Rows for MotionSegment: times accumulated from the durations, paper type per kind."""
    rows_in = r.raw.get("segments")
    if not isinstance(rows_in, list) or not rows_in:
        raise r.fail("segments", "missing: give at least one [[segments]] table")
    rows: list[dict[str, Any]] = []
    t = 0.0
    speed = speed0_m_s
    for i, d in enumerate(rows_in):
        pre = f"segments[{i}]"
        row = _segment_values(r, pre, d)
        kind = row["kind"]
        paper_type, speed = _paper_type(r, pre, row, speed)
        if kind == "square":
            duration = row.get("sides", 4) * (row["leg_duration_s"] + row["turn_duration_s"])
        else:
            duration = row["duration_s"]
        row.pop("duration_s", None)
        row.update(start_s=t, end_s=t + duration, paper_type=paper_type)
        rows.append(row)
        t += duration
    return rows


def _segment_values(r: Reader, pre: str, d: Any) -> dict[str, Any]:
    """One [[segments]] table (key prefix pre) as a row of checked values: a known kind, its required keys
    present, no others, each value of its type and in range."""
    if not isinstance(d, dict):
        raise r.fail(pre, "expected a table")
    kind = d.get("kind")
    if kind not in SEGMENT_KEYS:
        raise r.fail(
            f"{pre}.kind", f"unknown segment kind {kind!r} (known: {', '.join(SEGMENT_KINDS)})"
        )
    allowed = SEGMENT_KEYS[kind]
    r.check_keys(pre, ("kind", *allowed), d)
    for key in allowed:
        if key not in d and key not in _OPTIONAL_KEYS:
            raise r.fail(f"{pre}.{key}", f"missing (needed by a {kind} segment)")
    row: dict[str, Any] = {"kind": kind}
    for key in allowed:
        if key in d:
            row[key] = _segment_value(r, f"{pre}.{key}", key, d[key])
    for key in ("duration_s", "leg_duration_s", "turn_duration_s"):
        if key in row:
            r.require(row[key] > 0, f"{pre}.{key}", "must be positive")
    for key in ("peak_vertical_speed_m_s", "bank_deg"):
        if key in row:
            r.require(0 <= row[key] < 90, f"{pre}.{key}", "must be >= 0 (the kind gives the sign)")
    return row


def _segment_value(r: Reader, full: str, key: str, value: Any) -> Any:
    """A segment's value: a square's direction, turn order and number of sides as given, every other a number."""
    if key == "direction":
        r.require(value in ("left", "right"), full, "must be 'left' or 'right'")
        return value
    if key == "turn_first":
        r.require(isinstance(value, bool), full, "must be true or false")
        return value
    if key == "sides":
        r.require(
            isinstance(value, int) and not isinstance(value, bool) and value >= 1,
            full,
            "must be a positive integer",
        )
        return value
    return r.number(full, value)


def _paper_type(r: Reader, pre: str, row: dict[str, Any], speed: float) -> tuple[str, float]:
    """The segment's paper motion type and the speed (m/s) at its end, given the speed at its start: a static
    segment needs the vehicle at rest; a level one changes the speed (type I) or only holds it (-)."""
    kind = row["kind"]
    paper_type = _PAPER_TYPE.get(kind, "-")
    if kind == "static":
        r.require(
            speed == 0.0,
            pre,
            f"a static segment needs the vehicle at rest, speed is {speed} m/s",
        )
    elif kind == "level":
        r.require(
            "speed_end_m_s" in row or "speed_bump_m_s" in row,
            pre,
            "a level segment needs speed_end_m_s and/or speed_bump_m_s",
        )
        new_speed = row.get("speed_end_m_s", speed)
        r.require(new_speed >= 0, f"{pre}.speed_end_m_s", "must be >= 0")
        paper_type = "I" if (new_speed != speed or row.get("speed_bump_m_s", 0.0) != 0.0) else "-"
        speed = new_speed
    return paper_type, speed


def check_dvl_draws(r: Reader, dvl: Any) -> None:
    """The [dvl] keys of the stated noise, the per-run constant error and the drawn calibration (a DvlSpec): each
    bad one a GtsamDvlError naming it."""
    r.require(dvl.stated_noise_m_s >= 0, "dvl.stated_noise_m_s", "must be >= 0 (0: noise_m_s)")
    r.require(
        dvl.constant_error_sigma_m_s >= 0, "dvl.constant_error_sigma_m_s", "must be >= 0 (0: none)"
    )
    # 5 sigma below the mean must stay a positive scale
    r.require(
        0 <= dvl.draw_scale_sigma < dvl.scale / 5.0,
        "dvl.draw_scale_sigma",
        f"must be in [0, scale / 5 = {dvl.scale / 5.0:g}) (0: the scale as given)",
    )
    sigmas = dvl.draw_misalignment_sigma_deg
    r.require(
        all(0 <= s <= 10.0 for s in (sigmas if isinstance(sigmas, tuple) else (sigmas,))),
        "dvl.draw_misalignment_sigma_deg",
        "must be in [0, 10] deg (0: the misalignment as given)",
    )
