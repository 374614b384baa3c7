"""The surfaces' materials drawn anew (``laser.surface_draw``): each wall and box ranges with the bias of
its drawn reflectivity, and the default leaves the scans and the recording's settings as they were."""

from __future__ import annotations

import hashlib

import numpy as np
import yaml

from gtrig.sim.config import LaserSimConfig, SimConfig
from gtrig.sim.gtroom import make_scene
from gtrig.sim.lasers import (
    SURFACE_REFLECTIVITY_SPAN,
    WALL_REFLECTIVITY,
    _rays_world,
    simulate_fixed_scans,
    static_segments,
    surface_reflectivities,
)
from gtrig.sim.raycast import cast_segments
from gtrig.sim.recording import _config_key, _default_draw_settings


def test_a_draw_gives_each_surface_a_material_of_its_own():
    sc = make_scene(1)
    walls, boxes = surface_reflectivities(sc)
    assert np.all(walls == WALL_REFLECTIVITY) and np.array_equal(boxes, [b.reflectivity for b in sc.boxes])
    w3, b3 = surface_reflectivities(sc, 3)
    drawn = np.r_[w3, b3]
    lo, hi = SURFACE_REFLECTIVITY_SPAN
    assert np.all((drawn >= lo) & (drawn <= hi)) and np.unique(drawn).size == drawn.size
    assert np.array_equal(drawn, np.r_[surface_reflectivities(sc, 3)])  # seeded
    assert not np.allclose(drawn, np.r_[surface_reflectivities(sc, 4)])
    assert not np.allclose(drawn, np.r_[surface_reflectivities(make_scene(2), 3)])


def test_a_drawn_surface_ranges_by_its_own_bias():
    # the same scans and noise in the designed room and in a drawn one: every static return moves by the
    # bias difference of the surface it hits (within the 1 mm quantisation), and by more than that on some
    quiet = {"people": 0, "mixed_pixels": False, "dropout_prob": 0.0}
    sc = make_scene(1)
    logs = [simulate_fixed_scans(sc, None, np.array([[0.0, 0.1]]), SimConfig(laser=LaserSimConfig(
        surface_draw=k, **quiet)), 5)[0] for k in (0, 3)]
    k_bias = LaserSimConfig().reflectivity_bias_m
    moved = []
    for s in sc.rig_true.laser_scanners:
        T = s.T_world_scanner.matrix()
        segs, z_top, rho0 = static_segments(sc, T[:2, 3])
        rho3 = static_segments(sc, T[:2, 3], 3)[2]
        o, u, z0, dz, _ = _rays_world(T, s.angles_rad[:, None])
        _, hit = cast_segments(o, u, segs, z0, dz, z_top[None, None, :])
        hit = hit[:, 0]
        seen = hit >= 0
        expected = k_bias * (rho0[hit[seen]] - rho3[hit[seen]])  # dark ranges long: 0.5 - rho
        d = (logs[1][s.name].ranges_m - logs[0][s.name].ranges_m)[:, seen]
        assert np.all(np.abs(d - expected) <= 0.001 + 1e-9), s.name
        moved.append(np.abs(expected))
    assert np.max(np.concatenate(moved)) > 0.002


def test_the_default_leaves_the_scans_and_the_settings_as_they_were():
    # the fixed scans of seed 1's room as the simulator wrote them before surfaces could be drawn
    scans, _ = simulate_fixed_scans(make_scene(1), None, np.array([[0.0, 0.2]]), SimConfig(seed=1), 7)
    h = hashlib.sha256()
    for name in sorted(scans):
        h.update(np.ascontiguousarray(scans[name].stamps_s).tobytes())
        h.update(np.ascontiguousarray(scans[name].ranges_m).tobytes())
    assert h.hexdigest()[:16] == "6beb70193584d02a"
    # sim_config.yaml and the resume key name the draw only when it is one
    cfg = SimConfig(seed=0)
    assert "surface_draw" not in yaml.safe_dump(cfg.model_dump(mode="json", exclude=_default_draw_settings(cfg)))
    drawn = cfg.model_copy(update={"laser": LaserSimConfig(surface_draw=2)})
    assert yaml.safe_load(yaml.safe_dump(drawn.model_dump(mode="json", exclude=_default_draw_settings(drawn))))[
        "laser"]["surface_draw"] == 2
    assert _config_key(drawn) != _config_key(cfg)
