"""Gymnasium environments over the batched simulator: :class:`~pioneer.envs.env.NavEnv` (one
episode) and :class:`~pioneer.envs.vector.NavVectorEnv` (a native ``VectorEnv``). The ids are
registered by entry-point string in :mod:`pioneer.registration` (``import pioneer``)."""
