"""App. B random circulo-polygons: exact target asphericity, strict convexity, area ratio, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.shapes.generation import random_circulo_polygon, random_polygon_shapes


@pytest.mark.parametrize("sides, target", [(3, 1.05), (5, 1.1), (8, 1.01), (10, 1.05)])
def test_random_polygons_hit_the_target_and_stay_convex(sides, target):
    table = random_polygon_shapes(6, sides, target, 4)
    np.testing.assert_allclose(table.asphericity, target, rtol=1e-13)
    assert np.allclose(table.area[3:] / table.area[:3], 1.96, rtol=1e-12)
    for k in range(len(table)):
        v = table.vertex_list(k)
        e = np.roll(v, -1, axis=0) - v
        cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        assert np.all(cross > 0.0)
    # shapes differ (random), not copies of one
    assert np.ptp(table.radius[:3]) > 0.0


@pytest.mark.parametrize("sides, target, needle", [(2, 1.1, "--sides"), (5, 0.9, "--asphericity > 1"),
                                                   (10, 1.3, "lower --asphericity")])
def test_random_polygon_bad_input(sides, target, needle):
    with pytest.raises(ValueError, match=needle):
        random_circulo_polygon(sides, target, np.random.default_rng(1), max_steps=2000)
