"""Torch building blocks shared by the students (:mod:`pioneer.learn`) and the learned
baselines (:mod:`pioneer.baselines.crowdnav`): seeded layers and safetensors checkpoints."""
