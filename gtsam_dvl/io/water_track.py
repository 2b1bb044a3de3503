"""Water track from a topic of its own: drivers that publish the DVL's velocity relative to the water as a separate
twist topic (geometry_msgs/msg/TwistWithCovarianceStamped or TwistStamped) next to the bottom track. Its pings
join the DVL's in stamp order, marked water_track (core/types.py DvlData: not valid as velocity over ground,
their velocity kept), without beams or altitude."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.types import BeamData, DvlData

WATER_TOPIC_TYPES = (
    "geometry_msgs/msg/TwistWithCovarianceStamped",
    "geometry_msgs/msg/TwistStamped",
)


def as_water_track(water: DvlData) -> DvlData:
    """The pings of a water-track topic marked as such: water_track True, valid False (DvlData's contract), the
    velocity and its covariance as read (NaN velocity: the driver's invalid ping)."""
    m = len(water)
    return DvlData(
        water.t,
        water.d_v,
        water.d_cov,
        np.zeros(m, bool),
        None,
        water.frame_id,
        water_track=np.ones(m, bool),
        altitude=np.full(m, np.nan),
    )


def merge_pings(dvl: DvlData, water: DvlData) -> DvlData:
    """dvl's pings and water's (as_water_track) in stamp order (dvl's first at equal stamps). Beams: the water
    pings' are invalid, NaN, with dvl's first beam geometry; altitude: NaN for them (None when dvl has none and
    water none either)."""
    order = np.argsort(np.concatenate([dvl.t, water.t]), kind="stable")
    m, n = len(dvl), len(water)

    def join(
        a: np.ndarray | None, b: np.ndarray | None, fill: float | bool, shape: tuple[int, ...]
    ) -> np.ndarray:
        a = np.full((m, *shape), fill) if a is None else a
        b = np.full((n, *shape), fill) if b is None else b
        return np.concatenate([a, b])[order]

    beams = None
    if dvl.beams is not None:
        b = dvl.beams
        nb = b.d_u.shape[1]
        d_u = np.broadcast_to(b.d_u[0] if m else np.zeros((nb, 3)), (n, nb, 3))
        beams = BeamData(
            np.concatenate([b.d_u, d_u])[order],
            join(b.v, None, np.nan, (nb,)),
            join(b.range, None, np.nan, (nb,)),
            join(b.valid, None, False, (nb,)).astype(bool),
        )
    altitude = (
        None
        if dvl.altitude is None and water.altitude is None
        else join(dvl.altitude, water.altitude, np.nan, ())
    )
    return DvlData(
        np.concatenate([dvl.t, water.t])[order],
        join(dvl.d_v, water.d_v, np.nan, (3,)),
        join(dvl.d_cov, water.d_cov, np.nan, (3, 3)),
        join(dvl.valid, water.valid, False, ()).astype(bool),
        beams,
        dvl.frame_id,
        join(dvl.water_track, water.water_track, False, ()).astype(bool),
        noise_free=dvl.noise_free,
        altitude=altitude,
    )
