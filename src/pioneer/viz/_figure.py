"""matplotlib for the figure modules: the Agg-backed ``pyplot`` and the one way a finished
figure is written (optional super title, tight layout, atomic PNG, figure closed)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

from pioneer.io import atomic_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["pyplot", "save_figure"]


def pyplot():  # type: ignore[no-untyped-def]
    """``matplotlib.pyplot`` on the non-interactive Agg backend (imported lazily)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - matplotlib is a core dependency
        raise ImportError("plotting needs matplotlib: pip install matplotlib") from exc
    return plt


def save_figure(
    fig: Figure,
    path: str | os.PathLike[str],
    *,
    title: str = "",
    dpi: float | None = None,
    tight: bool = True,
) -> None:
    """Finish ``fig`` and write it to ``path`` as a PNG (atomically), then close it.

    A non-empty ``title`` becomes the figure's super title (font size 10); ``tight`` applies
    ``tight_layout`` (pass ``False`` for a figure made with ``layout="constrained"``); ``dpi``
    [dots per inch] of the file, ``None`` keeps matplotlib's default (the figure's own dpi).
    """
    if title:
        fig.suptitle(title, fontsize=10)
    if tight:
        fig.tight_layout()
    options: dict[str, Any] = {} if dpi is None else {"dpi": dpi}
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", **options)
    pyplot().close(fig)
