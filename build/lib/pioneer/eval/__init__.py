"""Evaluation: running episodes of any policy and summarising them."""

from pioneer.eval.episode import EpisodeRecord, Trajectory, run_episode

__all__ = ["EpisodeRecord", "Trajectory", "run_episode"]
