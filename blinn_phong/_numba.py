"""Whether the compiled (numba) engine can be used: a leaf module every engine may import.

The ``engine`` argument's values (:data:`ENGINES`) and their resolution (:func:`use_compiled`) are
declared once, in :mod:`compositing._engine`, for both packages; this module re-exports them.
"""

from __future__ import annotations

from compositing._engine import ENGINES, numba_available, use_compiled

__all__ = ["ENGINES", "numba_available", "use_compiled"]
