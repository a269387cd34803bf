"""The OpenGL blend factors and equations as the specification lists them, typed for the tests.

OpenGL 4.6 core profile, §17.3.6.1–2, tables 17.1 (equations) and 17.2 (factors), without
the ``GL_`` prefix and without the dual-source ``SRC1_*`` factors. Written out here
independently of ``compositing.gl_blend`` so the tests can check its tables against the spec.
"""

FACTOR_NAMES = (
    "ZERO",
    "ONE",
    "SRC_COLOR",
    "ONE_MINUS_SRC_COLOR",
    "DST_COLOR",
    "ONE_MINUS_DST_COLOR",
    "SRC_ALPHA",
    "ONE_MINUS_SRC_ALPHA",
    "DST_ALPHA",
    "ONE_MINUS_DST_ALPHA",
    "CONSTANT_COLOR",
    "ONE_MINUS_CONSTANT_COLOR",
    "CONSTANT_ALPHA",
    "ONE_MINUS_CONSTANT_ALPHA",
    "SRC_ALPHA_SATURATE",
)
EQUATION_NAMES = ("FUNC_ADD", "FUNC_SUBTRACT", "FUNC_REVERSE_SUBTRACT", "MIN", "MAX")
