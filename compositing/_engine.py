"""The ``engine`` argument, declared once for ``compositing`` and ``blinn_phong``.

Every function of both packages that takes ``engine=`` accepts the values of :data:`ENGINES`:
``"numpy"`` (the reference), ``"numba"`` (the compiled twin; an error when numba cannot be
imported) or ``"auto"`` (compiled when numba imports, else numpy). :func:`use_compiled` checks
the value and says which one runs; a caller may keep ``"auto"`` on numpy for inputs too small to
pay for a compilation (``compositing.gl_blend``, ``compositing.operators``).

A leaf module: it imports nothing of the project (``blinn_phong._numba`` re-exports it).
"""

from __future__ import annotations

import difflib
import functools
from typing import Final

__all__ = ["ENGINES", "numba_available", "use_compiled"]

#: The values of every ``engine`` argument.
ENGINES: Final[tuple[str, ...]] = ("auto", "numpy", "numba")


@functools.lru_cache(maxsize=1)
def numba_available() -> bool:
    """True when numba imports (the compiled path can be used)."""
    try:
        import numba  # noqa: F401
    except Exception:
        return False
    return True


def use_compiled(engine: object, name: str = "engine") -> bool:
    """Check an ``engine`` argument and say whether it selects the compiled path.

    Args:
        engine: what the caller received: one of :data:`ENGINES`.
        name: the argument's name as the caller spells it, for the error message.

    Returns:
        False for ``"numpy"``; True for ``"numba"``; for ``"auto"``, whether numba imports.

    Raises:
        ValueError: ``engine`` is not one of :data:`ENGINES` (``"{name}: expected one of ('auto',
            'numpy', 'numba'), got 'x'"``, with a "did you mean" for a near miss), or it is
            ``"numba"`` and numba cannot be imported.
    """
    if not isinstance(engine, str) or engine not in ENGINES:
        message = f"{name}: expected one of {ENGINES}, got {engine!r}"
        if isinstance(engine, str):
            close = difflib.get_close_matches(engine.lower(), ENGINES, n=1, cutoff=0.6)
            if close:
                message += f"; did you mean {close[0]!r}?"
        raise ValueError(message)
    if engine == "numpy":
        return False
    if numba_available():
        return True
    if engine == "numba":
        raise ValueError(f"{name}: 'numba' requested but numba cannot be imported")
    return False
