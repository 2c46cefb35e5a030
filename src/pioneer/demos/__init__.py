"""Sources of demonstrations: scripted courteous and careless drivers (:mod:`.scripted`), their
episode generator (:mod:`.generate`) and keyboard teleoperation (:mod:`.teleop`). The dataset
format they write is :mod:`pioneer.reward.dataset`."""
