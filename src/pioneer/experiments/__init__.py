"""Experiments built from the layers below: ``pioneer reproduce`` (:mod:`.reproduce`), the
world calibration (:mod:`.calibration`) and the static reward study (:mod:`.static_study`)."""
