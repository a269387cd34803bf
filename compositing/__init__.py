"""compositing: alpha compositing on premultiplied, linear-light RGBA arrays.

Convention everywhere: float32 (float64 accepted and kept), linear light,
premultiplied RGBA in the last axis, shape ``(..., 4)``, row 0 at the top.
"""

from .factors import ALL_OPERATORS, EXTRA_OPERATORS, FACTORS, OPERATORS, PORTER_DUFF

__all__ = ["ALL_OPERATORS", "EXTRA_OPERATORS", "FACTORS", "OPERATORS", "PORTER_DUFF"]
