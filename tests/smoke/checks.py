"""The loop both smoke scripts (``check.py``, ``runtime_check.py``) share: run each check,
print one line for it and, last, the JSON line ``{"passed": N, "failed": N}`` that
``dist.py`` reads. Standard library only: it runs in the venv under test."""

from __future__ import annotations

import json
import time
import traceback
from collections.abc import Callable, Sequence


def run_checks(checks: Sequence[tuple[str, Callable[[], str]]]) -> int:
    """Run ``checks`` (name, function returning a note); exit code 1 if any raised."""
    passed = failed = 0
    for name, check in checks:
        t0 = time.perf_counter()
        try:
            note = check()
        except Exception:
            failed += 1
            print(f"  FAIL {name}\n" + traceback.format_exc(), flush=True)
        else:
            passed += 1
            print(f"  ok   {name} ({time.perf_counter() - t0:.1f} s): {note}", flush=True)
    print(json.dumps({"passed": passed, "failed": failed}))
    return 1 if failed else 0
