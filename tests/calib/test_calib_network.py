"""Network calibration on projected corners of the simulated GT room: the joint BA recovers the truth."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.calib import synth
from gtrig.calib.chessboard import Board
from gtrig.calib.network import calibrate_network
from gtrig.errors import InputError
from gtrig.sim.gtroom import make_scene

BOARD = Board(9, 5, 0.1)
PAIRS = [("cam0", "cam1"), ("cam1", "cam2"), ("cam2", "cam3")]


@pytest.fixture(scope="module")
def solved():
    sc = make_scene(3)
    prob = synth.synthetic_network(
        sc.rig_true,
        sc.rig_nominal,
        BOARD,
        sc.T_board1_board2_true,
        sc.T_board1_board2_nominal,
        sc.T_world_board,
        PAIRS,
        ["cam1"],
        5,
        0.05,
        np.random.default_rng(3),
    )
    return sc, prob, calibrate_network(prob)


def test_joint_recovers_truth_and_beats_the_chain(solved) -> None:
    sc, _, res = solved
    for c in sc.rig_true.cameras:
        dt, dr = geo.pose_error(res.joint[c.name].T_world_cam, c.T_world_cam.matrix())
        assert dt < 0.003 and np.degrees(dr) < 0.03, c.name
    T3 = sc.rig_true.camera("cam3").T_world_cam.matrix()
    joint3 = geo.pose_error(res.joint["cam3"].T_world_cam, T3)[0]
    chain3 = geo.pose_error(res.chain["cam3"], T3)[0]
    assert res.chain_path["cam3"] == ["cam1", "cam2", "cam3"]
    assert chain3 > 2 * joint3
    # the double board's transform is estimated, not taken at its nominal value
    assert geo.pose_error(res.T_board1_board2, sc.T_board1_board2_true)[0] < 0.5e-3


def test_uncertainty_is_consistent(solved) -> None:
    sc, _, res = solved
    assert 0.03 < res.sigma_px < 0.08  # the 0.05 px of noise put in
    for c in sc.rig_true.cameras:
        e = res.joint[c.name].T_world_cam[:3, 3] - c.T_world_cam.matrix()[:3, 3]
        s = res.joint[c.name].sigma_pos_m
        assert np.all(s > 0) and np.all(np.abs(e) < 5 * s + 1e-4), c.name
    assert set(res.rms_px_pair) == {"cam0-cam1", "cam1-cam2", "cam2-cam3"}
    assert all(v < 0.15 for v in res.rms_px_pair.values())


def test_no_world_board_is_a_one_line_error(solved) -> None:
    _, prob, _ = solved
    from dataclasses import replace

    with pytest.raises(InputError, match="world board"):
        calibrate_network(replace(prob, world_views=[]))
