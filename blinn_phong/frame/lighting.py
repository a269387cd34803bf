"""The lighting equation — the one place it is written.

OpenGL 2.1 specification §2.14.1 ("Lighting"), evaluated in eye space at any set
of points (vertices for Gouraud/flat shading, fragments for Phong shading)::

    c = e_cm + a_cm·a_cs + a_cm·Σ_amb I_amb
        + Σ_i att_i·spot_i·[ a_cm·a_cli
                             + vis_i·(n ⊙ l_i)·d_cm·d_cli
                             + vis_i·f_i·spec_i^s_rm·s_cm·s_cli ]

with ``u ⊙ v = max(u·v, 0)``,

* ``l_i`` the unit vector from the point to light i (``-direction`` for a directional light);
* ``f_i = 1`` if ``n·l_i > 0`` else 0 — a light behind the surface gives no highlight;
* ``spec_i = n ⊙ h_i`` with ``h_i = normalize(l_i + v)`` (Blinn 1977, the OpenGL form) or
  ``spec_i = r_i ⊙ v`` with ``r_i = 2(n·l_i)n - l_i`` (Phong 1975);
* ``v = -normalize(p)`` for a local viewer, ``(0, 0, 1)`` for a viewer at infinity;
* ``att_i = 1/(k_c + k_l·d + k_q·d²)`` for positional lights, 1 for directional; ``d`` is the
  **eye-space** distance from the point to the light, as in OpenGL (``‖VP_pli‖`` in eye
  coordinates); it differs from the world-space distance when the view matrix scales or shears;
* ``spot_i = (-l_i ⊙ s_i)^exponent`` if ``-l_i·s_i >= cos(cutoff)``, else 0; 1 for non-spots;
* ``vis_i`` an optional per-point, per-light visibility in [0, 1] (shadows), 1 by default;
* ``I_amb`` the :class:`~blinn_phong.model.lights.AmbientLight` radiances, ``a_cs`` the scene's global
  ambient.

Alpha is the material opacity (the alpha of ``d_cm``). Colours are linear and
not clamped here; the GL-compatibility clamp is the separate, explicit
:func:`gl_clamp`.

:func:`shade` has two engines: ``"numpy"`` (vectorised over points) and ``"numba"``
(a compiled per-point loop). Both evaluate the per-light terms with the same three
functions, :func:`_view_vector`, :func:`_light_direction` and :func:`_reflection`, written
once on numbers that may be arrays (numpy) or scalars (compiled by numba); the engines
agree to 1e-12. The compiled per-point body is :func:`point_terms`, which the fused frame
kernel of :mod:`blinn_phong.frame.fused` (interpolation, lighting and the frame buffers in one
pass) calls as well.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from blinn_phong._checks import float_array
from blinn_phong._numba import use_compiled
from blinn_phong.model.lights import Light
from blinn_phong.model.scene import LightModel, Material

__all__ = [
    "UNIT_NORMAL_TOLERANCE",
    "EyeLights",
    "ShadingTerms",
    "gl_clamp",
    "light_tables",
    "lights_in_eye_space",
    "material_tables",
    "point_terms",
    "shade",
    "shade_many",
]

#: A normal given to :func:`shade` must have length 0 or ``1 ± UNIT_NORMAL_TOLERANCE``
#: (float32 normalisation is good to about 1e-7; a longer normal would scale the light).
UNIT_NORMAL_TOLERANCE = 1e-5


@dataclass(frozen=True, eq=False)
class EyeLights:
    """Directional, point and spot lights moved to eye space, as arrays over the L lights.

    Attributes:
        position: (L, 4) homogeneous eye-space position; w = 0 for directional lights,
            whose xyz is then the unit direction *towards* the light (OpenGL's GL_POSITION).
        spot_direction: (L, 3) unit eye-space spot axis (zeros for non-spots).
        cos_cutoff: (L,) cosine of the spot cut-off; -inf for non-spots (no cone).
        spot_exponent: (L,) spot exponent (0 for non-spots).
        attenuation: (L, 3) (k_c, k_l, k_q); (1, 0, 0) for directional lights.
        ambient, diffuse, specular: (L, 3) light colours a_cli, d_cli, s_cli.
        ambient_lights: (3,) sum of the AmbientLight radiances.
        source: (L,) index of each light in the scene's ``lights`` tuple.
    """

    position: np.ndarray
    spot_direction: np.ndarray
    cos_cutoff: np.ndarray
    spot_exponent: np.ndarray
    attenuation: np.ndarray
    ambient: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray
    ambient_lights: np.ndarray
    source: np.ndarray

    def __len__(self) -> int:
        return len(self.position)


def lights_in_eye_space(lights: Sequence[Light], view: np.ndarray) -> EyeLights:
    """Move world-space lights to eye space with the 4×4 ``view`` matrix (as ``glLight`` does).

    Positions transform as points, directions with the upper 3×3 (then renormalised).
    AmbientLights are summed into ``ambient_lights``.
    """
    view = np.asarray(view, dtype=np.float64)
    rows = []
    ambient_sum = np.zeros(3)
    for index, light in enumerate(lights):
        eye_space = getattr(light, "eye_space", None)
        if eye_space is None:
            raise TypeError(f"lights[{index}]: unsupported light type {type(light).__name__}")
        row = eye_space(view)
        if row is None:  # an ambient light: no position, its radiance joins the ambient term
            ambient_sum += np.asarray(light.radiance)
            continue
        rows.append((*row, light.ambient, light.diffuse, light.specular, index))
    n = len(rows)

    def col(i: int, shape: tuple[int, ...]) -> np.ndarray:
        return np.array([r[i] for r in rows], dtype=np.float64).reshape((n, *shape))

    return EyeLights(
        position=col(0, (4,)),
        spot_direction=col(1, (3,)),
        cos_cutoff=col(2, ()),
        spot_exponent=col(3, ()),
        attenuation=col(4, (3,)),
        ambient=col(5, (3,)),
        diffuse=col(6, (3,)),
        specular=col(7, (3,)),
        ambient_lights=ambient_sum,
        source=np.array([r[8] for r in rows], dtype=np.int64),
    )


@dataclass(frozen=True, eq=False)
class ShadingTerms:
    """The lighting equation's terms at N points (linear RGB, unclamped).

    Attributes:
        ambient: (N, 3) emission + all ambient terms (global, AmbientLights, per-light ambient).
        diffuse: (N, 3) Σ Lambert terms.
        specular: (N, 3) Σ specular terms.
        alpha: (N,) material opacity.
        diffuse_per_light, specular_per_light: (N, L, 3) per-light terms (before
            visibility) when requested with ``per_light=True``, else None.
    """

    ambient: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray
    alpha: np.ndarray
    diffuse_per_light: np.ndarray | None = None
    specular_per_light: np.ndarray | None = None

    @property
    def color(self) -> np.ndarray:
        """(N, 3) total ``ambient + diffuse + specular``."""
        return self.ambient + self.diffuse + self.specular


def _points_and_normals(points: object, normals: object) -> tuple[np.ndarray, np.ndarray]:
    """``points`` and ``normals`` as finite (N, 3) float64 arrays, normals of length 0 or 1, or raise."""
    p = float_array(points, "points", (None, 3))
    n = float_array(normals, "normals", (len(p), 3))
    length = np.sqrt(np.einsum("ij,ij->i", n, n))
    bad = np.flatnonzero((length != 0.0) & (np.abs(length - 1.0) > UNIT_NORMAL_TOLERANCE))
    if len(bad):
        raise ValueError(
            f"normals: expected unit vectors (length 1 ± {UNIT_NORMAL_TOLERANCE:g}) or zero vectors; "
            f"got {len(bad)} of {len(n)} with other lengths (row {bad[0]}: length {float(length[bad[0]])!r})"
        )
    return p, n


def _visibility(visibility: object, count: int, n_lights: int) -> np.ndarray:
    """``visibility`` as an (N, L) or per-channel (N, L, 3) float64 array of values in [0, 1], or raise."""
    per_channel = np.ndim(visibility) == 3  # (N, L, 3): coloured shadows, one factor per RGB channel
    vis = float_array(visibility, "visibility", (count, n_lights, 3) if per_channel else (count, n_lights))
    outside = int(np.count_nonzero((vis < 0) | (vis > 1)))
    if outside:
        raise ValueError(
            f"visibility: expected values in [0, 1]; got {outside} of {vis.size} outside, "
            f"range [{vis.min()!r}, {vis.max()!r}]"
        )
    return vis


def shade(
    points: np.ndarray,
    normals: np.ndarray,
    material: Material,
    lights: EyeLights,
    *,
    global_ambient: Sequence[float] | np.ndarray = (0.2, 0.2, 0.2),
    model: LightModel | None = None,
    visibility: np.ndarray | None = None,
    per_light: bool = False,
    engine: str = "numpy",
) -> ShadingTerms:
    """Evaluate the lighting equation (module docstring) at eye-space points.

    Args:
        points: (N, 3) finite eye-space positions (eye at the origin looking down -Z).
        normals: (N, 3) finite eye-space unit normals, length ``1 ±`` :data:`UNIT_NORMAL_TOLERANCE`
            (1e-5), or zero vectors, which receive only ambient and emission. For back faces
            under two-sided lighting pass the flipped normal.
        material: the surface material (use the back material for back faces).
        lights: from :func:`lights_in_eye_space`.
        global_ambient: ``a_cs`` (linear RGB).
        model: the specular form and viewer model (``specular``, ``local_viewer``);
            defaults to :class:`~blinn_phong.model.scene.LightModel` ().
        visibility: optional (N, L) factors in [0, 1] multiplying each light's diffuse
            and specular terms (1 = lit; e.g. from a shadow test), or (N, L, 3) one factor
            per RGB channel (coloured shadows through transparent casters). L = ``len(lights)``.
        per_light: also return the (N, L, 3) per-light diffuse and specular terms.
        engine: ``"numpy"`` (reference), ``"numba"`` (compiled; not with ``per_light``),
            or ``"auto"`` (numba when it imports and ``per_light`` is False).

    Returns:
        :class:`ShadingTerms` in float64.

    Raises:
        ValueError: a NaN/Inf point or normal (the count is reported), a normal of another
            length, or a visibility outside [0, 1], naming the argument.
    """
    model = LightModel() if model is None else model
    p, n = _points_and_normals(points, normals)
    count = len(p)
    n_lights = len(lights)
    if visibility is not None:
        vis = _visibility(visibility, count, n_lights)
    if use_compiled(engine) and not per_light:
        ids = np.zeros(count, np.int64)
        return _shade_compiled(
            p, n, ids, [material], lights, global_ambient, model, None if visibility is None else vis
        )
    a_cm = np.asarray(material.ambient)
    d_cm = np.asarray(material.diffuse)
    s_cm = np.asarray(material.specular)
    ambient = np.broadcast_to(
        np.asarray(material.emission)
        + a_cm * (np.asarray(global_ambient, dtype=np.float64) + lights.ambient_lights),
        (count, 3),
    ).copy()
    diffuse = np.zeros((count, 3))
    specular = np.zeros((count, 3))
    alpha = np.full(count, material.opacity)
    dpl = np.zeros((count, n_lights, 3)) if per_light else None
    spl = np.zeros((count, n_lights, 3)) if per_light else None
    px, py, pz = p[:, 0], p[:, 1], p[:, 2]
    vx, vy, vz = _view_vector(px, py, pz, model.local_viewer)
    blinn = model.specular == "blinn"
    for i in range(n_lights):
        lx, ly, lz, att = _light_direction(
            px,
            py,
            pz,
            lights.position[i],
            lights.spot_direction[i],
            lights.cos_cutoff[i],
            lights.spot_exponent[i],
            lights.attenuation[i],
        )
        lambert, highlight = _reflection(
            n[:, 0], n[:, 1], n[:, 2], lx, ly, lz, vx, vy, vz, att, material.shininess, blinn
        )
        ambient += np.broadcast_to(att, (count,))[:, None] * (a_cm * lights.ambient[i])
        d_i = lambert[:, None] * (d_cm * lights.diffuse[i])
        s_i = highlight[:, None] * (s_cm * lights.specular[i])
        if per_light:
            dpl[:, i] = d_i
            spl[:, i] = s_i
        if visibility is not None:
            w_i = vis[:, i] if vis.ndim == 3 else vis[:, i : i + 1]  # (N, 3) per channel, or (N, 1)
            d_i = d_i * w_i
            s_i = s_i * w_i
        diffuse += d_i
        specular += s_i
    return ShadingTerms(ambient, diffuse, specular, alpha, dpl, spl)


def shade_many(
    points: np.ndarray,
    normals: np.ndarray,
    material_ids: np.ndarray,
    materials: Sequence[Material],
    lights: EyeLights,
    *,
    global_ambient: Sequence[float] | np.ndarray = (0.2, 0.2, 0.2),
    model: LightModel | None = None,
    visibility: np.ndarray | None = None,
    engine: str = "numpy",
) -> ShadingTerms:
    """:func:`shade` for points with different materials: point i uses ``materials[material_ids[i]]``.

    Arguments as for :func:`shade`, plus ``material_ids`` (N,) integer indices into
    ``materials``. The numpy engine calls :func:`shade` once per material; the numba
    engine evaluates all points in one compiled pass.
    """
    model = LightModel() if model is None else model
    ids = np.asarray(material_ids)
    p, n = _points_and_normals(points, normals)
    vis = None if visibility is None else _visibility(visibility, len(p), len(lights))
    if ids.shape != (len(p),) or (ids.size and ids.dtype.kind not in "iu"):
        raise ValueError(
            f"material_ids: expected ({len(p)},) integers, got shape {ids.shape} dtype {ids.dtype}"
        )
    if ids.size and (ids.min() < 0 or ids.max() >= len(materials)):
        raise ValueError(
            f"material_ids: expected indices in [0, {len(materials) - 1}], got [{ids.min()}, {ids.max()}]"
        )
    if use_compiled(engine):
        ids64 = ids.astype(np.int64)
        return _shade_compiled(p, n, ids64, list(materials), lights, global_ambient, model, vis)
    out = {k: np.zeros((len(p), 3)) for k in ("ambient", "diffuse", "specular")}
    alpha = np.zeros(len(p))
    for mid in np.unique(ids):
        sel = np.flatnonzero(ids == mid)
        terms = shade(
            p[sel],
            n[sel],
            materials[int(mid)],
            lights,
            global_ambient=global_ambient,
            model=model,
            visibility=None if vis is None else vis[sel],
        )
        out["ambient"][sel] = terms.ambient
        out["diffuse"][sel] = terms.diffuse
        out["specular"][sel] = terms.specular
        alpha[sel] = terms.alpha
    return ShadingTerms(out["ambient"], out["diffuse"], out["specular"], alpha)


#: A float64 array (numpy engine) or a float scalar (inside the numba kernel).
_Num = np.ndarray | float


def _view_vector(px: _Num, py: _Num, pz: _Num, local_viewer: bool) -> tuple[_Num, _Num, _Num]:
    """Unit vector ``v`` from eye-space point(s) to the eye, as three components.

    ``-p/|p|`` for a local viewer, ``(0, 0, 1)`` at the eye itself (any direction would do);
    ``(0, 0, 1)`` for a viewer at infinity (OpenGL 2.1 §2.14.1). The plain length
    ``sqrt(x² + y² + z²)``: eye-space distances of a scene are far from its float64
    under/overflow (below 1e-154 or above 1e154).

    Written once for both engines: on (N,) float64 arrays for the numpy engine, and on
    float scalars inside the numba kernel (only arithmetic, comparisons and ``np.sqrt``,
    ``np.abs``, ``np.maximum``; a comparison's bool acts as 0 or 1).
    """
    if local_viewer:
        length = np.sqrt(px * px + py * py + pz * pz)
        at_eye = length == 0.0
        length = length + at_eye
        return -px / length, -py / length, -pz / length + at_eye
    zero = 0.0 * px
    return zero, zero, zero + 1.0


def _light_direction(
    px: _Num,
    py: _Num,
    pz: _Num,
    position: np.ndarray,
    spot_direction: np.ndarray,
    cos_cutoff: float,
    spot_exponent: float,
    attenuation: np.ndarray,
) -> tuple[_Num, _Num, _Num, _Num]:
    """Unit vector ``l`` from point(s) ``p`` towards one light, and its ``att·spot`` (OpenGL 2.1 §2.14.1).

    ``l = position.xyz`` for a directional light (``position.w = 0``, xyz already the unit
    direction towards it), else ``normalize(position.xyz/w − p)`` (zero at the light itself;
    plain length, as in :func:`_view_vector`); ``att = 1/(k_c + k_l·d + k_q·d²)`` with ``d``
    the eye-space distance (p and the light are both in eye space) for positional lights,
    1 for directional ones; ``spot = max(−l·s, 0)^exponent`` inside the cone
    ``−l·s ≥ cos(cutoff)``, 0 outside, 1 for non-spots (``cos_cutoff = −inf``).

    ``position`` (4,), ``spot_direction`` (3,), ``cos_cutoff``, ``spot_exponent`` and
    ``attenuation`` (3,) are one light's rows of :class:`EyeLights`. Written once for both
    engines (see :func:`_view_vector`): ``p`` is (N,) arrays or float scalars.
    """
    w = position[3]
    if w == 0.0:
        lx, ly, lz = position[0] + 0.0 * px, position[1] + 0.0 * py, position[2] + 0.0 * pz
        att = 1.0 + 0.0 * px
    else:
        tx, ty, tz = position[0] / w - px, position[1] / w - py, position[2] / w - pz
        dist = np.sqrt(tx * tx + ty * ty + tz * tz)
        length = dist + (dist == 0.0)
        lx, ly, lz = tx / length, ty / length, tz / length
        att = 1.0 / (attenuation[0] + attenuation[1] * dist + attenuation[2] * dist * dist)
    if np.isfinite(cos_cutoff):
        c = -(lx * spot_direction[0] + ly * spot_direction[1] + lz * spot_direction[2])
        att = att * ((c >= cos_cutoff) * np.maximum(c, 0.0) ** spot_exponent)
    return lx, ly, lz, att


def _reflection(
    nx: _Num,
    ny: _Num,
    nz: _Num,
    lx: _Num,
    ly: _Num,
    lz: _Num,
    vx: _Num,
    vy: _Num,
    vz: _Num,
    att: _Num,
    shininess: float,
    blinn: bool,
) -> tuple[_Num, _Num]:
    """One light's diffuse and specular factors ``(att·(n ⊙ l), att·f·spec^s_rm)`` (OpenGL 2.1 §2.14.1).

    They multiply the colours ``d_cm·d_cli`` and ``s_cm·s_cli``. ``f = 1`` if ``n·l > 0``
    else 0; ``spec = n ⊙ h`` with ``h = normalize(l + v)`` (Blinn 1977, ``blinn`` true) or
    ``r ⊙ v`` with ``r = 2(n·l)n − l`` (Phong 1975). Both factors are 0 where ``att = 0``
    or ``n·l ≤ 0`` (the compiled kernel skips those lights). Written once for both engines
    (see :func:`_view_vector`).
    """
    n_dot_l = nx * lx + ny * ly + nz * lz
    if blinn:
        hx, hy, hz = lx + vx, ly + vy, lz + vz
        h_length = np.sqrt(hx * hx + hy * hy + hz * hz)
        base = (nx * hx + ny * hy + nz * hz) / (h_length + (h_length == 0.0))
    else:
        base = (
            (2.0 * n_dot_l * nx - lx) * vx + (2.0 * n_dot_l * ny - ly) * vy + (2.0 * n_dot_l * nz - lz) * vz
        )
    highlight = (n_dot_l > 0.0) * np.maximum(base, 0.0) ** shininess
    return att * np.maximum(n_dot_l, 0.0), att * highlight


def _shade_compiled(
    p: np.ndarray,
    n: np.ndarray,
    ids: np.ndarray,
    materials: list[Material],
    lights: EyeLights,
    global_ambient: Sequence[float] | np.ndarray,
    model: LightModel,
    vis: np.ndarray | None,
) -> ShadingTerms:
    """:func:`shade_many` through the compiled kernel (same equation, same argument meaning)."""
    base, a_cm, d_cm, s_cm, shininess, opacity = material_tables(materials, lights, global_ambient)
    count = len(p)
    ambient = np.empty((count, 3))
    diffuse = np.empty((count, 3))
    specular = np.empty((count, 3))
    if vis is None:
        vis3 = np.zeros((0, 0, 1))
    else:  # (N, L) -> (N, L, 1); (N, L, 3) per channel
        vis3 = np.ascontiguousarray(vis if vis.ndim == 3 else vis[:, :, None], dtype=np.float64)
    from compositing._threads import in_shares

    in_shares(
        _kernel(), count,
        np.ascontiguousarray(p), np.ascontiguousarray(n), ids, base, a_cm, d_cm, s_cm, shininess,
        light_tables(lights), bool(model.local_viewer), model.specular == "blinn", vis3,
        ambient, diffuse, specular,
    )  # fmt: skip
    return ShadingTerms(ambient, diffuse, specular, opacity[ids])


@functools.lru_cache(maxsize=1)
def point_terms() -> object:  # a numba dispatcher
    """The lighting equation at one eye-space point, compiled: the per-point body of every kernel.

    ``point_terms()(q, px, py, pz, nx, ny, nz, m, bases, a_cms, d_cms, s_cms, shininesses,
    pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe, local_viewer, blinn, has_vis,
    vis, group_of, group_sum)`` returns the nine floats ``(ambient, diffuse, specular)`` RGB of the module
    docstring's equation at the point ``p`` with unit normal ``n`` (zero normals get ambient and
    emission only), for material ``m`` of the tables of :func:`material_tables` (``bases`` =
    emission + ``a_cm``·(global ambient + AmbientLights)) and the lights of an
    :class:`EyeLights` as the arrays of :func:`light_tables`. With ``has_vis``, ``vis[q, i, c]``
    (an (N, L, K) array, K = 1 or 3: one factor per light, or one per RGB channel) multiplies
    light i's diffuse and specular terms.

    Light groups (:mod:`blinn_phong.frame.light_groups`): ``group_of`` (L,) int64 is each light's group
    (−1: none) and ``group_sum`` a (G, 3) float64 scratch; light i's ambient, diffuse and specular
    terms (the ones summed into the result) are also added into ``group_sum[group_of[i]]``. An
    empty ``group_of`` (shape (0,)) turns this off (``group_sum`` is then not touched).

    It evaluates each light with the same Python functions as the numpy engine
    (:func:`_view_vector`, :func:`_light_direction`, :func:`_reflection`), compiled for scalars
    and inlined; the lighting kernel of :func:`shade` and the fused frame kernel of
    :mod:`blinn_phong.frame.fused` both call it, so the equation is written once. (Arrays are passed
    one by one and light rows as tuples of scalars: inside a per-point loop, array views and
    arrays unpacked from tuples cost a reference count each.)
    """
    import numba
    from numba.extending import overload

    # The same Python functions as the numpy engine's, compiled for scalars and inlined.
    for shared in (_view_vector, _light_direction, _reflection):
        overload(shared, strict=False, inline="always")(lambda *args, f=shared: f)

    @numba.njit(inline="always", cache=True)
    def terms(
        q, px, py, pz, nx, ny, nz, m, bases, a_cms, d_cms, s_cms, shininesses,
        pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe, local_viewer, blinn, has_vis, vis,
        group_of, group_sum,
    ):  # fmt: skip  # pragma: no cover - compiled
        vx, vy, vz = _view_vector(px, py, pz, local_viewer)
        grouped = group_of.shape[0] > 0
        ar, ag, ab = bases[m, 0], bases[m, 1], bases[m, 2]
        a0, a1, a2 = a_cms[m, 0], a_cms[m, 1], a_cms[m, 2]
        d0, d1, d2 = d_cms[m, 0], d_cms[m, 1], d_cms[m, 2]
        s0, s1, s2 = s_cms[m, 0], s_cms[m, 1], s_cms[m, 2]
        shininess = shininesses[m]
        dr = dg = db = 0.0
        sr = sg = sb = 0.0
        per_channel = has_vis and vis.shape[2] == 3
        for i in range(pos.shape[0]):
            lx, ly, lz, att = _light_direction(
                px, py, pz,
                (pos[i, 0], pos[i, 1], pos[i, 2], pos[i, 3]),
                (spot_dir[i, 0], spot_dir[i, 1], spot_dir[i, 2]),
                cos_cut[i], spot_exp[i], (atten[i, 0], atten[i, 1], atten[i, 2]),
            )  # fmt: skip
            tr, tg, tb = att * (a0 * l_amb[i, 0]), att * (a1 * l_amb[i, 1]), att * (a2 * l_amb[i, 2])
            ar += tr
            ag += tg
            ab += tb
            group = group_of[i] if grouped else -1
            if group >= 0:  # the light's group: its ambient term ...
                group_sum[group, 0] += tr
                group_sum[group, 1] += tg
                group_sum[group, 2] += tb
            if att == 0.0 or nx * lx + ny * ly + nz * lz <= 0.0:
                continue  # _reflection gives exactly 0 here
            fd, fs = _reflection(nx, ny, nz, lx, ly, lz, vx, vy, vz, att, shininess, blinn)
            wr = wg = wb = 1.0
            if has_vis:
                wr = vis[q, i, 0]
                wg = vis[q, i, 1] if per_channel else wr
                wb = vis[q, i, 2] if per_channel else wr
            tr = fd * (d0 * l_dif[i, 0]) * wr
            tg = fd * (d1 * l_dif[i, 1]) * wg
            tb = fd * (d2 * l_dif[i, 2]) * wb
            ur = fs * (s0 * l_spe[i, 0]) * wr
            ug = fs * (s1 * l_spe[i, 1]) * wg
            ub = fs * (s2 * l_spe[i, 2]) * wb
            dr += tr
            dg += tg
            db += tb
            sr += ur
            sg += ug
            sb += ub
            if group >= 0:  # ... and its diffuse and specular terms
                group_sum[group, 0] += tr + ur
                group_sum[group, 1] += tg + ug
                group_sum[group, 2] += tb + ub
        return ar, ag, ab, dr, dg, db, sr, sg, sb

    return terms


def light_tables(lights: EyeLights) -> tuple[np.ndarray, ...]:
    """The ``lights`` tuple of :func:`point_terms` (contiguous float64 arrays of an :class:`EyeLights`)."""
    return tuple(
        np.ascontiguousarray(a, dtype=np.float64)
        for a in (
            lights.position,
            lights.spot_direction,
            lights.cos_cutoff,
            lights.spot_exponent,
            lights.attenuation,
            lights.ambient,
            lights.diffuse,
            lights.specular,
        )
    )


def material_tables(
    materials: Sequence[Material], lights: EyeLights, global_ambient: Sequence[float] | np.ndarray
) -> tuple[np.ndarray, ...]:
    """Per-material arrays ``(base, a_cm, d_cm, s_cm, shininess, opacity)`` of :func:`point_terms`.

    ``base`` (M, 3) is emission + ``a_cm``·(global ambient + the AmbientLights' sum), the terms
    that do not depend on the point.
    """
    a_cm = np.array([m.ambient for m in materials], dtype=np.float64).reshape(-1, 3)
    emission = np.array([m.emission for m in materials], dtype=np.float64).reshape(-1, 3)
    base = emission + a_cm * (np.asarray(global_ambient, dtype=np.float64) + lights.ambient_lights)
    return (
        base,
        a_cm,
        np.array([m.diffuse for m in materials], dtype=np.float64).reshape(-1, 3),
        np.array([m.specular for m in materials], dtype=np.float64).reshape(-1, 3),
        np.array([m.shininess for m in materials], dtype=np.float64),
        np.array([m.opacity for m in materials], dtype=np.float64),
    )


#: :func:`point_terms`'s dispatcher once compiled kernels need it (a global: see :func:`_kernel`).
_point_terms: object = None


@functools.lru_cache(maxsize=1)
def _kernel() -> object:  # a numba dispatcher
    """The lighting equation as a compiled per-point loop over :func:`point_terms`, for the points
    ``share`` (shares of all points run on threads: :func:`compositing._threads.in_shares`)."""
    import numba

    global _point_terms
    # A module global, not a closure variable: numba's disk-cache key hashes closure variables,
    # and a compiled function in one would change it in every process (no cache hit, ever).
    _point_terms = point_terms()

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def kernel(
        share,
        p, n, ids, bases, a_cms, d_cms, s_cms, shininesses, lights, local_viewer, blinn, vis,
        out_amb, out_dif, out_spe,
    ):  # fmt: skip  # pragma: no cover - compiled
        count = p.shape[0]
        pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe = lights
        has_vis = vis.shape[0] == count and vis.shape[1] == pos.shape[0] and count > 0
        no_groups = np.zeros(0, np.int64)
        no_sums = np.zeros((0, 3))
        for q in share:
            ar, ag, ab, dr, dg, db, sr, sg, sb = _point_terms(
                q, p[q, 0], p[q, 1], p[q, 2], n[q, 0], n[q, 1], n[q, 2], ids[q], bases, a_cms, d_cms,
                s_cms, shininesses, pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe,
                local_viewer, blinn, has_vis, vis, no_groups, no_sums,
            )  # fmt: skip
            out_amb[q, 0], out_amb[q, 1], out_amb[q, 2] = ar, ag, ab
            out_dif[q, 0], out_dif[q, 1], out_dif[q, 2] = dr, dg, db
            out_spe[q, 0], out_spe[q, 1], out_spe[q, 2] = sr, sg, sb

    return kernel


def gl_clamp(terms: ShadingTerms, *, separate_specular: bool) -> tuple[np.ndarray, np.ndarray]:
    """OpenGL's per-vertex colour clamp (2.1 §2.14.6, ``GL_CLAMP_VERTEX_COLOR``), primary and secondary.

    ``GL_SINGLE_COLOR``: primary = clamp(ambient + diffuse + specular, 0, 1), secondary = 0.
    ``GL_SEPARATE_SPECULAR_COLOR``: primary = clamp(ambient + diffuse), secondary = clamp(specular);
    the fragment colour is their sum (colour sum, §3.9), clamped again by a fixed-point framebuffer.

    Returns:
        (primary (N, 3), secondary (N, 3)).
    """
    if separate_specular:
        return np.clip(terms.ambient + terms.diffuse, 0.0, 1.0), np.clip(terms.specular, 0.0, 1.0)
    return np.clip(terms.color, 0.0, 1.0), np.zeros_like(terms.specular)
