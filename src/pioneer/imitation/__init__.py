"""Imitation learning by dataset aggregation, shared by the LiDAR students
(:mod:`pioneer.learn.dagger`) and CrowdNav++'s imitation warm start
(:mod:`pioneer.baselines.crowdnav.imitation`).

DAgger (Ross, Gordon and Bagnell, AISTATS 2011): round 0 is driven by the expert, every later
round by the model fitted on the aggregate of the rounds before it, and the expert labels
every visited state. :mod:`.store` keeps a run on disk (one file per episode, written
atomically, so a rerun resumes where it stopped, and the run's settings, so a rerun with other
settings is refused); :mod:`.rounds` is the round loop, with the per-method parts passed in
(how an episode is collected and labelled, what the aggregate is, how a model is fitted);
:mod:`.worker` what a collecting process shares (the expert-labelled driver, the cache).

numpy only; the methods bring their own models.
"""

from pioneer.imitation.rounds import Collector, Fitted, Method, Step, run_rounds
from pioneer.imitation.store import RunFolder, save_episode

__all__ = ["Collector", "Fitted", "Method", "RunFolder", "Step", "run_rounds", "save_episode"]
