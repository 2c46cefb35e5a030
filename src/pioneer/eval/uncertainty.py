"""The safe/risky uncertainty analysis (paper §V-B.2, Table IV) from evaluation records.

A frame is one decision of a student in an evaluation episode; its clearance is the distance
from the robot's centre to the nearest human's surface in the state the decision was made in
(``frames`` of :class:`pioneer.eval.episode.EpisodeRecord`; the paper's clearance, what d₁
measures). Frames with clearance > 0.8 m are safe, the rest risky (no humans in range: safe).
Per class: frame counts and mean aleatoric and epistemic uncertainty (paper Table IV); beyond
the paper, the AUROC of each uncertainty as a detector of risky frames (0.5: no signal, 1:
perfect).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import DataError, expect
from pioneer.eval.episode import RISKY_DISTANCE_M
from pioneer.stats import auroc

__all__ = ["MEASURES", "PAPER_TABLE_IV", "frame_arrays", "safe_risky", "table_iv_markdown"]

# Paper Table IV: (safe epistemic, safe aleatoric, risky epistemic, risky aleatoric) and the
# frame counts (safe, risky) quoted in §V-B.2.
PAPER_TABLE_IV: dict[str, dict[str, float]] = {
    "hr-rl": {
        "epistemic_safe": 0.290,
        "aleatoric_safe": 0.310,
        "epistemic_risky": 0.382,
        "aleatoric_risky": 0.407,
        "frames_safe": 62374,
        "frames_risky": 5467,
    },
    "hl-rr": {
        "epistemic_safe": 0.342,
        "aleatoric_safe": 0.270,
        "epistemic_risky": 0.523,
        "aleatoric_risky": 0.426,
        "frames_safe": 67806,
        "frames_risky": 3245,
    },
}


MEASURES = ("clearance", "gap")  # the frame series a risky threshold can apply to


def frame_arrays(
    records: Iterable[Mapping[str, Any]], measure: str = "clearance"
) -> dict[str, NDArray[np.float64]]:
    """Concatenate the per-frame series of ``records`` (those without frames are skipped);
    ``None`` (no human in range / not reported) becomes ``inf`` for a distance, NaN otherwise.

    The ``distance`` column holds the frames' ``measure``: ``clearance`` (robot centre →
    nearest human surface, the paper's) or ``gap`` (surface to surface, docs/simulator.md)."""
    if measure not in MEASURES:
        raise DataError(expect("distance measure", f"one of {MEASURES}", measure, "pick one"))
    cols: dict[str, list[float]] = {"distance": [], "aleatoric": [], "epistemic": []}
    for rec in records:
        fr = rec.get("frames")
        if not fr:
            continue
        if measure not in fr:
            raise DataError(
                expect(
                    "record frames",
                    f"a {measure!r} series",
                    sorted(fr),
                    "re-run the evaluation into a new --out (older records lack it)",
                )
            )
        n = len(fr[measure])
        if not len(fr["aleatoric"]) == len(fr["epistemic"]) == n:
            raise DataError(
                expect("record frames", "equally long series", rec.get("seed"), "re-run it")
            )
        for key, src, missing in (
            ("distance", measure, math.inf),
            ("aleatoric", "aleatoric", math.nan),
            ("epistemic", "epistemic", math.nan),
        ):
            cols[key].extend(missing if x is None else float(x) for x in fr[src])
    return {k: np.asarray(v, dtype=np.float64) for k, v in cols.items()}


def safe_risky(
    records: Iterable[Mapping[str, Any]],
    threshold: float = RISKY_DISTANCE_M,
    measure: str = "clearance",
) -> dict[str, Any]:
    """Counts, mean uncertainties per class and AUROCs for the frames of ``records``; a frame
    is risky when its ``measure`` (see :func:`frame_arrays`) is ≤ ``threshold``."""
    fr = frame_arrays(records, measure)
    ok = np.isfinite(fr["aleatoric"]) & np.isfinite(fr["epistemic"])
    clear, ale, epi = fr["distance"][ok], fr["aleatoric"][ok], fr["epistemic"][ok]
    risky = clear <= threshold
    out: dict[str, Any] = {
        "threshold_m": threshold,
        "measure": measure,
        "frames_safe": int((~risky).sum()),
        "frames_risky": int(risky.sum()),
    }
    for name, v in (("aleatoric", ale), ("epistemic", epi)):
        out[f"{name}_safe"] = float(v[~risky].mean()) if (~risky).any() else math.nan
        out[f"{name}_risky"] = float(v[risky].mean()) if risky.any() else math.nan
        out[f"auroc_{name}"] = auroc(v, risky)  # NaN when a class is empty
    return out


def _f(x: float, digits: int = 3) -> str:
    """``digits`` decimals, or 3 significant digits for small values (ours are ~1e−3)."""
    if not (isinstance(x, int | float) and math.isfinite(x)):
        return "–"
    return f"{x:.3g}" if 0 < abs(x) < 0.1 else f"{x:.{digits}f}"


def table_iv_markdown(results: Mapping[str, Mapping[str, Any]], scenarios: Sequence[str]) -> str:
    """Table IV laid out like the paper's (Epi., Ale. per class), ours beside the paper's,
    plus frame counts and AUROCs."""
    lines = [
        "| Scenario | | risky if centre → surface ≤ | Safe Epi. | Safe Ale. | Risky Epi. "
        "| Risky Ale. | frames safe / risky | AUROC epi. | AUROC ale. |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for sc in scenarios:
        r = results.get(sc)
        if r is None:
            continue
        lines.append(
            f"| {sc} | ours | {_f(r['threshold_m'], 2)} m | "
            f"{_f(r['epistemic_safe'])} | {_f(r['aleatoric_safe'])} | "
            f"{_f(r['epistemic_risky'])} | {_f(r['aleatoric_risky'])} | "
            f"{r['frames_safe']:,} / {r['frames_risky']:,} | {_f(r['auroc_epistemic'])} | "
            f"{_f(r['auroc_aleatoric'])} |"
        )
        p = PAPER_TABLE_IV.get(sc)
        if p is not None:
            lines.append(
                f"| | paper | {RISKY_DISTANCE_M:g} m | {p['epistemic_safe']:.3f} | "
                f"{p['aleatoric_safe']:.3f} | "
                f"{p['epistemic_risky']:.3f} | {p['aleatoric_risky']:.3f} | "
                f"{int(p['frames_safe']):,} / {int(p['frames_risky']):,} | – | – |"
            )
    return "\n".join(lines) + "\n"
