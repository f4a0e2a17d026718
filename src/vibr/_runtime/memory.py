"""The memory vibr may use, and the one-line refusal of work that would exceed it."""

from __future__ import annotations

from ..errors import VibrInputError


def available_memory() -> int | None:
    """Bytes vibr may use: ``$VIBR_MEMORY_LIMIT_GB`` when set, else the system's
    MemAvailable (Linux), else None (no check)."""
    import os

    env = os.environ.get("VIBR_MEMORY_LIMIT_GB")
    if env:
        try:
            return int(float(env) * 2**30)
        except ValueError:
            raise VibrInputError(f"VIBR_MEMORY_LIMIT_GB must be a number of GB, got {env!r}") from None
    try:
        with open("/proc/meminfo") as f:
            for ln in f:
                if ln.startswith("MemAvailable:"):
                    return int(ln.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_memory(need: float, what: str, way_out: str, source=None) -> None:
    """Refuse (one line) when ``need`` bytes exceed :func:`available_memory`."""
    avail = available_memory()
    if avail is not None and need > avail:
        raise VibrInputError(f"{what} needs about {need / 2**30:.1f} GB of memory, "
                             f"{avail / 2**30:.1f} GB available: {way_out}", source)

