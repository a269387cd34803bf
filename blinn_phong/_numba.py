"""Whether the compiled (numba) engine can be used: a leaf module every engine may import."""

from __future__ import annotations

import functools

__all__ = ["numba_available"]


@functools.lru_cache(maxsize=1)
def numba_available() -> bool:
    """True when numba imports (the compiled path can be used)."""
    try:
        import numba  # noqa: F401
    except Exception:
        return False
    return True
