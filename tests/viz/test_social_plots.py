"""The pictures of the social-navigation measures: clearance violins and occupancy maps."""

from __future__ import annotations

import numpy as np
from PIL import Image

from pioneer.sim import get_scenario
from pioneer.viz.social import plot_clearance_distribution, plot_occupancy

ZONES = (("intimate", 0.0, 0.45), ("personal", 0.45, 1.2), ("social", 1.2, 3.6))


def test_clearance_violins_one_panel_per_scenario(tmp_path):
    rng = np.random.default_rng(0)
    panels = {
        "HR-RL": {"teacher": rng.uniform(0.3, 3.0, 200), "goal": [0.1, np.inf, 0.5, 9.0]},
        "HL-RR": {"teacher": rng.uniform(0.3, 3.0, 50), "empty": [np.inf]},
    }
    out = tmp_path / "clear.png"
    plot_clearance_distribution(panels, out, zones=ZONES, title="t")
    with Image.open(out) as im:
        assert im.format == "PNG" and im.size[1] > im.size[0] / 3
    plot_clearance_distribution({"X": {}}, tmp_path / "none.png")  # no data: a note, no error
    assert (tmp_path / "none.png").stat().st_size > 0


def test_occupancy_panels_with_walls(tmp_path):
    world = get_scenario("hr-rl").world()
    rng = np.random.default_rng(1)
    positions = {f"p{k}": rng.normal([0.0, -1.0], 0.5, size=(300, 2)) for k in range(5)}
    positions["nothing"] = np.zeros((0, 2))
    out = tmp_path / "occ.png"
    plot_occupancy(world, positions, out, title="where")
    with Image.open(out) as im:
        assert im.format == "PNG"
        pixels = np.asarray(im.convert("RGB")).reshape(-1, 3)
    assert (pixels.sum(axis=1) < 60).any()  # the walls, in black
    assert not list(tmp_path.glob(".*"))  # no temporary file left
