"""Independent reference implementations the tests and benchmarks compare against.

Nothing here is used by the product code: these modules drive real third-party
software (Mesa's OpenGL through EGL, Blender's compositor) so that our numpy
kernels can be checked against an implementation we did not write.
"""
