"""Whether figures can be drawn: matplotlib is the optional extra ``[plots]``, so the service
runs without it and only drawing asks for it, with an error that says how to install it."""

from __future__ import annotations


class PlotsUnavailableError(RuntimeError):
    """matplotlib, the optional extra that draws the figures, is not installed."""

    def __init__(self) -> None:
        super().__init__(
            "drawing figures needs matplotlib, which is not installed: pip install 'gcs-utm[plots]'"
        )


def require_plots() -> None:
    """Raise :class:`PlotsUnavailableError` unless matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise PlotsUnavailableError() from exc
