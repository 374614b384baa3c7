"""The area a plan covers when none is given: the rig's room outline when it gives one, else the hull of
its scanners and reference points."""

from __future__ import annotations

import numpy as np

from gtrig.plan.grid import area_grid, default_area, points_in_polygon
from gtrig.sim.gtroom import design_rig


def test_default_area_is_the_rooms_outline_when_the_rig_gives_one():
    rig = design_rig()
    hull = default_area(rig)
    outline = ((-6.0, -4.0), (7.0, -4.0), (7.0, 8.0), (-6.0, 8.0))
    with_outline = rig.model_copy(update={"world": rig.world.model_copy(update={"outline_xy": outline})})
    area = default_area(with_outline)
    assert np.array_equal(area, np.array(outline))
    assert not np.array_equal(hull, area)
    cells = area_grid(area, 0.5, 1).cells_xy
    assert points_in_polygon(cells, np.array(outline)).all()
    assert cells.shape[0] == area_grid(area, 0.5, 1).n_cells > area_grid(hull, 0.5, 1).n_cells
