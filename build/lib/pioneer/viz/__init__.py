"""Drawing: the only package that imports plotting libraries (Pillow, matplotlib)."""

from pioneer.viz.frames import render_frame, save_gif
from pioneer.viz.plots import plot_learning_curve, plot_trajectory

__all__ = ["plot_learning_curve", "plot_trajectory", "render_frame", "save_gif"]
