"""compositing: alpha compositing on premultiplied, linear-light RGBA arrays.

Convention everywhere: float32 (float64 accepted and kept), linear light,
premultiplied RGBA in the last axis, shape ``(..., 4)``, row 0 at the top.
Image files: :mod:`compositing.io`. Input checks: :mod:`compositing.validate`.
"""

# _kernel_cache registers this package's kernels with the per-user cache; _threads makes OpenMP's
# threads sleep between numba's parallel loops (its docstring says why)
from . import _kernel_cache, _threads  # noqa: F401
from .alpha import premultiply, unpremultiply
from .factors import ALL_OPERATORS, EXTRA_OPERATORS, FACTORS, OPERATORS, PORTER_DUFF
from .operators import composite, resolve_operator
from .stack import composite_stack, composite_stack_front_to_back
from .transparency import absorption, coverage_union, emission, partial_occlusion

__all__ = [
    "ALL_OPERATORS",
    "EXTRA_OPERATORS",
    "FACTORS",
    "OPERATORS",
    "PORTER_DUFF",
    "absorption",
    "composite",
    "composite_stack",
    "composite_stack_front_to_back",
    "coverage_union",
    "emission",
    "partial_occlusion",
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
