"""PioneeR performance benchmarks, split by area; ``benchmarks/run.py`` is the entry point.

- ``common``   the plan, interleaved timing, statistics and targets, the host probe, the scene
- ``results``  the machine and source description, the printed table, the JSON file
- ``sim``      env steps, ray casting, the batched world step
- ``psf``      the same scene in pysocialforce, against our env and world step
- ``vector``   the native vector env against Gymnasium's ``SyncVectorEnv``
- ``control``  the density reward, the teacher's decision, CVaR-BF
- ``learn``    the students (ONNX Runtime, PyTorch), a DAgger run, CrowdNav++
- ``memory``   peak RSS of fresh processes (env, deploy runtime)
"""
