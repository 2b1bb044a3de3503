"""The water current in the outputs: the summary's headline (verdict, per-depth table, errors against the truth),
the result MCAP's /gtsam_dvl/water_current topics (decoded with mcap_ros2 against what the result holds) and the
figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.app.plots.current_plots import plot_current
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.io.result_writer import TOPICS, write_result_log
from tests.support.water import N_C, with_water_track
from tests.support.water import water_config as _config


@pytest.fixture(scope="module")
def water_run(sim_paper3d_short: LogData) -> tuple[LogData, NavResult]:
    log = with_water_track(sim_paper3d_short)
    truth = log.truth
    assert truth is not None
    # the truth current of the stretch, for the summary's errors (the log's other states: no current measured)
    truth.n_c = np.tile(N_C, (len(truth.t), 1))
    return log, smooth_batch(log, _config(log, "auto"))


def test_summary_and_result_topics(water_run: tuple[LogData, NavResult], tmp_path: Path) -> None:
    log, res = water_run
    s = summary(res, log)
    wc = s["water_current"]
    assert wc["water_track_pings"] == int(np.sum(log.dvl.water_track))
    assert "determined" in wc["verdict"] and wc["by_depth"]
    # determined states' current against the (constant) truth: within its sigmas
    assert wc["errors"]["rms_m_s"] < 0.05 and wc["errors"]["max_abs_z"] < 5.0
    path = write_result_log(tmp_path / "result.mcap", res, log, s)
    got: dict[str, list[list[float]]] = {
        TOPICS["water_current"]: [],
        TOPICS["water_current_sigma"]: [],
    }
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=list(got)):
            got[channel.topic].append([msg.vector.x, msg.vector.y, msg.vector.z])
    assert res.water_current is not None
    profile = res.water_current.as_dict()
    np.testing.assert_array_equal(
        np.array(got[TOPICS["water_current"]])[:, :2],
        np.stack([profile["east_m_s"], profile["north_m_s"]], axis=1),
    )
    np.testing.assert_array_equal(
        np.array(got[TOPICS["water_current_sigma"]])[:, 1], profile["north_sigma_m_s"]
    )


def test_current_figure(water_run: tuple[LogData, NavResult], tmp_path: Path) -> None:
    log, res = water_run
    assert log.truth is not None
    png = plot_current(
        res.water_current, tmp_path / "water_current.png", log.truth.t, log.truth.n_c
    )
    assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
