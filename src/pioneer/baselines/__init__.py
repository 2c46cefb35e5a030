"""The paper's baselines (Table I): the classic controllers (:mod:`.classic`: go-to-goal, DWA,
social force), CVaR-BF (:mod:`~pioneer.baselines.cvar_bf`) and CrowdNav++
(:mod:`~pioneer.baselines.crowdnav`, needs torch).

Each is a :class:`~pioneer.envs.policy.Policy`, built by name through
:mod:`pioneer.control.registry`; importing this package imports none of them.
"""
