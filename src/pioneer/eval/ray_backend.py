"""The evaluation harness's Ray backend (``--backend ray``, extra ``distributed``): the same
stream as the local pool's, on a Ray cluster or a local Ray, with a cluster that cannot be
reached refused in one line before Ray retries it."""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Generator
from typing import Any

from pioneer.errors import ConfigError, expect

__all__ = ["RAY_CONNECT_TIMEOUT_S", "check_reachable", "ray_stream"]


def ray_stream(
    pairs: list[tuple[str, Any]],
    tasks: list[Any],
    address: str | None,
    run: Callable[[Any], dict[str, Any]],
    build: Callable[[tuple[str, Any]], dict[str, Any]],
) -> Generator[Any, None, None]:
    """The harness's ``stream`` on Ray (:mod:`pioneer.eval.harness` says what it yields):
    ``build`` every (scenario, policy) pair remotely first, then ``run`` the ``tasks`` the
    caller filled in meanwhile, yielding each record as it finishes. On an interruption the
    tasks are cancelled and a Ray this call started is shut down."""
    if address:
        check_reachable(address)
    try:
        import ray
    except ImportError as exc:
        raise ConfigError(
            expect(
                "backend",
                "ray installed",
                "not installed",
                "pip install 'pioneer-nav[distributed]'",
            )
        ) from exc
    started = not ray.is_initialized()
    if started:
        _ray_init(ray, address)
    from pioneer.sim.scenarios import SCENARIOS_ENV

    files = os.environ.get(SCENARIOS_ENV)  # scenario files: the same paths on every node
    remote: Any = ray.remote(run)
    builder: Any = ray.remote(build)
    if files:
        env = {"env_vars": {SCENARIOS_ENV: files}}
        remote, builder = (ray.remote(runtime_env=env)(f) for f in (run, build))
    refs: list[Any] = []
    try:
        made = ray.get([builder.remote(pair) for pair in pairs])
        yield {(sc, spec.row): m for (sc, spec), m in zip(pairs, made, strict=True)}
        refs = [remote.remote(t) for t in tasks]
        while refs:
            done, refs = ray.wait(refs, num_returns=1)
            yield ray.get(done[0])
    except BaseException:  # interrupted or abandoned: stop the tasks, and the Ray we started
        for ref in refs:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
        raise


RAY_CONNECT_TIMEOUT_S = 5.0  # [s] to open a TCP connection to a Ray cluster's address


def check_reachable(address: str) -> None:
    """Refuse, in one line naming it, a Ray address (``HOST:PORT`` or ``ray://HOST:PORT``)
    where nothing accepts a connection — before Ray retries it for minutes with pages of
    warnings. ``auto``, ``local`` and other forms are left to Ray."""
    import socket

    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        return
    try:
        with socket.create_connection((host.strip("[]"), int(port)), RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise ConfigError(
            expect(
                "--ray-address",
                "the address of a running Ray cluster",
                f"{address} ({why})",
                "start the cluster (ray start --head) or fix the address; without "
                "--ray-address a local Ray starts",
            )
        ) from exc


def _ray_init(ray: Any, address: str | None) -> None:
    """``ray.init``, keeping this process's SIGTERM handler (Ray sets its own, which exits
    without the interruption's line); a cluster that cannot be joined is one line."""
    import logging

    main = threading.current_thread() is threading.main_thread()
    handler = signal.getsignal(signal.SIGTERM) if main else None
    try:
        ray.init(
            address=address,
            include_dashboard=False,
            log_to_driver=False,
            logging_level=logging.ERROR,
        )
    except (ConnectionError, TimeoutError, RuntimeError) as exc:
        raise ConfigError(
            expect(
                "--ray-address",
                "a Ray cluster to join",
                f"{address or 'a local Ray'} ({str(exc).splitlines()[0] if str(exc) else exc})",
                "start the cluster (ray start --head) or fix the address",
            )
        ) from exc
    if handler is not None:
        signal.signal(signal.SIGTERM, handler)
