"""Porter & Duff's (Fa, Fb) closed forms, typed from the paper for the tests.

Porter & Duff, "Compositing Digital Images", SIGGRAPH '84, table 1 (plus: Fa = Fb = 1).
Written out here independently of ``compositing.factors`` so that the tests compare the
factor table, the numpy kernels and Blender's node groups with the paper, not with
themselves. Each entry maps an operator name to ``(Fa, Fb)`` as functions of the source
and destination alpha ``(s, d)`` (numpy arrays).
"""

PAPER = {
    "clear": (lambda s, d: 0 * s, lambda s, d: 0 * s),
    "src": (lambda s, d: 1 + 0 * s, lambda s, d: 0 * s),
    "dst": (lambda s, d: 0 * s, lambda s, d: 1 + 0 * s),
    "src_over": (lambda s, d: 1 + 0 * s, lambda s, d: 1 - s),
    "dst_over": (lambda s, d: 1 - d, lambda s, d: 1 + 0 * s),
    "src_in": (lambda s, d: d, lambda s, d: 0 * s),
    "dst_in": (lambda s, d: 0 * s, lambda s, d: s),
    "src_out": (lambda s, d: 1 - d, lambda s, d: 0 * s),
    "dst_out": (lambda s, d: 0 * s, lambda s, d: 1 - s),
    "src_atop": (lambda s, d: d, lambda s, d: 1 - s),
    "dst_atop": (lambda s, d: 1 - d, lambda s, d: s),
    "xor": (lambda s, d: 1 - d, lambda s, d: 1 - s),
    "plus": (lambda s, d: 1 + 0 * s, lambda s, d: 1 + 0 * s),
}

#: The twelve operators of the paper's table, in its order (``plus`` is the paper's extra).
TWELVE = tuple(name for name in PAPER if name != "plus")
