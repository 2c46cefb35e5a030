"""Demonstrations: the dataset format, scripted demonstrators and keyboard teleoperation."""

from pioneer.demos.dataset import Dataset, FeatureMap, feature_map

__all__ = ["Dataset", "FeatureMap", "feature_map"]
