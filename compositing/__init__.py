"""compositing: alpha compositing on premultiplied, linear-light RGBA arrays.

Convention everywhere: float32 (float64 accepted and kept), linear light,
premultiplied RGBA in the last axis, shape ``(..., 4)``, row 0 at the top.
"""

from .alpha import premultiply, unpremultiply
from .factors import ALL_OPERATORS, EXTRA_OPERATORS, FACTORS, OPERATORS, PORTER_DUFF
from .operators import composite, resolve_operator

__all__ = [
    "ALL_OPERATORS",
    "EXTRA_OPERATORS",
    "FACTORS",
    "OPERATORS",
    "PORTER_DUFF",
    "composite",
    "premultiply",
    "resolve_operator",
    "unpremultiply",
]

try:  # the OpenGL blend-stage emulation lives in its own module
    from .gl_blend import gl_blend, gl_factors
except ImportError:  # pragma: no cover - only while that module is absent
    pass
else:
    __all__ += ["gl_blend", "gl_factors"]
