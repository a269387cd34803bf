"""What every shadow method is: :class:`ShadowMethod`, the one small interface each method of
:mod:`blinn_phong.shadows` implements, and :class:`ShadowFrame`, what the lights of one frame share.

A method says what the planner and the frame need to know of it — whether it is exact, whether
transparent casters colour its shadows, whether it casts rays with Embree (and what stands in
without it), the name of its cost model in ``calibration.json``, the parameters it takes — and
gives its visibility twice: for points alone (:attr:`ShadowMethod.visibility`, the numpy
reference or the compiled kernels by ``engine``) and for a frame's points
(:attr:`ShadowMethod.frame_visibility`, sharing one BVH, the ray culling tables and the screen
binning between the frame's lights). :mod:`blinn_phong.shadows.methods` holds the registry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: ``visibility(light, tris, points, normals, **params) -> (m,) visibility`` for checked float64
#: (n, 3, 3) casters and (m, 3) points and normals.
PointVisibility = Callable[..., np.ndarray]


def embree_available() -> bool:
    """True when ``embreex`` (Intel Embree) can be imported; Blender's own Python lacks it.

    The methods that cast rays (:attr:`ShadowMethod.uses_rays`) need it; without it the
    planner picks shadow volumes, exact too, for hard shadows.
    """
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass
class ShadowFrame:
    """What the lights of one frame share when their visibility is computed at its points.

    Attributes:
        scene: the frame's :class:`blinn_phong.model.scene.Scene`.
        tris: (T, 3, 3) float64 world-space triangles of the meshes that cast shadows.
        world: (N, 3) float64 world-space points (the frame's visible samples).
        normal: (N, 3) float64 their unit face normals.
        compiled: the compiled engine (``engine="numba"`` for the methods that take one).
        mesh_of: (N,) the scene mesh of each point, or None; with the compiled engine, hard
            ray-traced and planar shadows then trace only the rays the geometry cannot answer
            (:mod:`blinn_phong.shadows.ray_culling`).
        binning: the points' screen tiles for shadow volumes
            (:func:`blinn_phong.shadows.volume.pixel_binning`), or None.
        aim: where soft lights face, or None (the centre of the casters' bounds).
        transmittance: (T, 3) per-caster RGB transmittance when some light's method is coloured
            and a caster lets light through, else None (the result is then (N,) per light).
        cache: the frame's shared tables between lights (culling tables, plane heights).
    """

    scene: Any
    tris: np.ndarray
    world: np.ndarray
    normal: np.ndarray
    compiled: bool
    mesh_of: np.ndarray | None = None
    binning: tuple | None = None
    aim: np.ndarray | None = None
    transmittance: np.ndarray | None = None
    cache: dict[object, object] = field(default_factory=dict)

    @property
    def engine(self) -> str:
        """``numba`` or ``numpy``: the engine of the methods that take one."""
        return "numba" if self.compiled else "numpy"

    @property
    def culled(self) -> bool:
        """True when shadow rays are culled (the compiled engine, with each point's mesh known)."""
        return self.compiled and self.mesh_of is not None

    def ray_scene(self) -> object:
        """The frame's one BVH of :attr:`tris` (:func:`blinn_phong.shadows.raytrace.cached_ray_scene`)."""
        if "ray_scene" not in self.cache:
            from blinn_phong.shadows.raytrace import cached_ray_scene  # Embree: imported only when used

            self.cache["ray_scene"] = cached_ray_scene(self.tris)
        return self.cache["ray_scene"]


#: ``frame_visibility(frame, light, params) -> (N,) or (N, 3) visibility`` at a frame's points.
FrameVisibility = Callable[[ShadowFrame, object, dict], np.ndarray]
#: ``choice_params(options, planned) -> (params, note)``: a choice's parameters from the caller's
#: :class:`blinn_phong.planning.frame_plan.ShadowOptions` and the planner's choice, and a note
#: for its reason ("" for none).
ChoiceParams = Callable[[Any, Any], tuple[dict, str]]
#: ``stand_in(light, options) -> (method, reason) | None``: the method that casts for a light
#: this one cannot cast for (soft shadows of a light without area), or None.
StandIn = Callable[[object, Any], "tuple[str, str] | None"]


@dataclass(frozen=True)
class ShadowMethod:
    """One shadow method: its facts and its visibility.

    Attributes:
        name: the name :func:`blinn_phong.render`, the planner and the add-on use.
        title: what the reasons call it ("a shadow map", "shadow volumes").
        summary: one line: what it computes (the docs quote it).
        exact: True when it classifies every point as the ray tracer does (up to grazing
            samples); False for approximations (a shadow map's texels) and for planar shadows,
            exact on their plane only.
        coloured: True when transparent casters colour its shadows (their RGB transmittance);
            the other methods cast full shadows.
        uses_rays: True when it casts rays with Embree (``embreex``).
        without_embree: the method that stands in when Embree is missing, or None.
        cost_model: its model's name in ``calibration.json`` (None: not modelled).
        parameters: the keyword parameters its visibility takes (``ShadowOptions`` fields and
            the planner's ``Choice.params``).
        visibility: the visibility of points alone, ``visibility(light, tris, points, normals,
            **params)``, by the numpy reference or the compiled kernels (``engine``).
        frame_visibility: the visibility at a frame's points, ``frame_visibility(frame, light,
            params)``, sharing the frame's BVH and tables; None calls :attr:`visibility` with the
            frame's engine.
        choice_params: its parameters for a frame from the caller's options and the planner's
            choice (:data:`ChoiceParams`); None: it takes none.
        stand_in: for a light it cannot cast for, the method that casts instead and why
            (:data:`StandIn`); None: it casts for every light.
    """

    name: str
    title: str
    summary: str
    exact: bool
    coloured: bool
    uses_rays: bool
    without_embree: str | None
    cost_model: str | None
    parameters: tuple[str, ...]
    visibility: PointVisibility
    frame_visibility: FrameVisibility | None = None
    choice_params: ChoiceParams | None = None
    stand_in: StandIn | None = None

    def params_for(self, options: Any, planned: Any) -> tuple[dict, str]:
        """Its parameters (and a note for the reason) from the caller's options and the planner's
        choice (:attr:`choice_params`)."""
        return ({}, "") if self.choice_params is None else self.choice_params(options, planned)

    def takes_engine(self) -> bool:
        """True when its visibility takes ``engine`` (numpy reference or compiled kernels)."""
        return "engine" in self.parameters

    def at_frame(self, frame: ShadowFrame, light: object, params: dict) -> np.ndarray:
        """Its visibility of ``light`` at the frame's points: (N,), or (N, 3) for coloured shadows."""
        if self.frame_visibility is not None:
            return self.frame_visibility(frame, light, params)
        extra = {"engine": frame.engine} if self.takes_engine() and "engine" not in params else {}
        return self.visibility(light, frame.tris, frame.world, frame.normal, **params, **extra)
