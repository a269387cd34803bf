"""Scenes, masks and error metrics that the tests and the benchmarks share.

Nothing here is used by the product code. The benchmarks measure on these scenes what the
tests check on a few of them, so both import them from here rather than from each other.
"""
