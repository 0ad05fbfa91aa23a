"""What every figure shares: the Agg backend (nothing is shown on screen) and :func:`save_figure`."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ..files import atomic_output  # noqa: E402

__all__ = ["save_figure"]


def save_figure(fig, path, dpi: int = 110) -> str:
    """Write ``fig`` as PNG to ``path``, close it, return the path as a string."""
    try:
        with atomic_output(path) as tmp:  # a temporary name, renamed when complete
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
    return str(path)
