"""Fog (atmospheric attenuation) as a function of eye distance.

OpenGL 2.1 §3.10 "Fog" (same in GL 1.1 §3.9): a fog factor ``f`` in [0, 1] blends the
fragment colour with the fog colour,

* ``GL_LINEAR``: ``f = (end − c) / (end − start)``
* ``GL_EXP``:    ``f = exp(−density · c)``
* ``GL_EXP2``:   ``f = exp(−(density · c)²)``

``f`` is clamped to [0, 1] by the specification, then ``C = f·C_r + (1 − f)·C_f`` on the
colour; alpha is left alone. ``c`` is the eye distance. Mesa's default distance mode is
``GL_EYE_PLANE_ABSOLUTE_NV``, ``c = |z_eye|`` (``main/fog.c``); ``GL_EYE_RADIAL_NV`` uses
``c = ‖p_eye‖``. Both are offered by :func:`eye_distance`.

On premultiplied RGBA the blend becomes ``rgb' = f·rgb + (1 − f)·α·C_f``, ``α' = α``,
which is the specification's straight-alpha formula multiplied through by ``α``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from blinn_phong._checks import choice_error, colour3, number, real_array

__all__ = ["FOG_MODES", "Fog", "apply_fog", "eye_distance", "fog_factor"]

FogMode = Literal["linear", "exp", "exp2"]
#: The three OpenGL fog modes.
FOG_MODES: tuple[str, ...] = ("linear", "exp", "exp2")


@dataclass(frozen=True)
class Fog:
    """Fog by eye distance (OpenGL 2.1 §3.10), passed to ``render(fog=...)``.

    Attributes:
        mode: ``"linear"`` — ``f = (end − c)/(end − start)``; ``"exp"`` — ``f = e^(−density·c)``;
            ``"exp2"`` — ``f = e^(−(density·c)²)``; f clamped to [0, 1]
            (:func:`blinn_phong.model.fog.fog_factor`).
        color: linear RGB fog colour ``C_f``.
        density: for ``exp``/``exp2``, per world unit, ≥ 0.
        start: for ``linear``, eye distance where fog begins.
        end: for ``linear``, eye distance of full fog (≠ start).
        distance: ``"plane"`` — ``c = |z_eye|`` (OpenGL's usual); ``"radial"`` — ``c = ‖p_eye‖``.

    Defaults are OpenGL's (GL_EXP, density 1, start 0, end 1, colour black).
    """

    mode: str = "exp"
    color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    density: float = 1.0
    start: float = 0.0
    end: float = 1.0
    distance: str = "plane"

    def __post_init__(self) -> None:
        if self.mode not in FOG_MODES:
            raise choice_error("Fog.mode", self.mode, FOG_MODES)
        object.__setattr__(self, "color", colour3(self.color, "Fog.color"))
        object.__setattr__(self, "density", number(self.density, "Fog.density", low=0.0))
        object.__setattr__(self, "start", number(self.start, "Fog.start"))
        object.__setattr__(self, "end", number(self.end, "Fog.end"))
        if self.mode == "linear" and self.start == self.end:
            raise ValueError(f"Fog.end: linear fog needs end != start, got start = end = {self.start}")
        if self.distance not in ("plane", "radial"):
            raise choice_error("Fog.distance", self.distance, ("plane", "radial"))


def eye_distance(eye_positions: np.ndarray, mode: Literal["plane", "radial"] = "plane") -> np.ndarray:
    """Fog distance ``c`` of eye-space points.

    Args:
        eye_positions: (..., 3) eye-space positions (camera at the origin looking down −z), any unit.
        mode: ``"plane"`` gives ``|z_eye|`` (GL_EYE_PLANE_ABSOLUTE_NV, Mesa's default);
            ``"radial"`` gives ``‖p_eye‖`` (GL_EYE_RADIAL_NV).

    Returns:
        (...) distances in the unit of the positions.
    """
    p = real_array(eye_positions, "eye_positions", last_axis=3)
    if mode == "plane":
        return np.abs(p[..., 2])
    if mode == "radial":
        return np.linalg.norm(p, axis=-1)
    raise ValueError(f"mode: expected 'plane' or 'radial', got {mode!r}")


def fog_factor(
    distance: np.ndarray | float,
    mode: FogMode = "exp",
    *,
    density: float = 1.0,
    start: float = 0.0,
    end: float = 1.0,
) -> np.ndarray:
    """The OpenGL fog factor ``f`` (1 = no fog, 0 = only fog) at eye distance ``c``.

    Formulas of OpenGL 2.1 §3.10 (see the module docstring), clamped to [0, 1] as the
    specification requires. Defaults are GL's (GL_EXP, density 1, start 0, end 1).

    Args:
        distance: eye distances ``c`` (any shape, ≥ 0 in practice), same unit as ``start``/``end``
            and ``1/density``.
        mode: ``"linear"``, ``"exp"`` or ``"exp2"``.
        density: fog density (≥ 0) for the exponential modes, per unit distance.
        start: distance where linear fog begins (f = 1), finite.
        end: distance where linear fog is complete (f = 0), finite and different from ``start``.

    Returns:
        Array of fog factors with the shape and float dtype of ``distance``.
    """
    c = real_array(distance, "distance")
    if mode == "linear":
        start = number(start, "start")
        end = number(end, "end")
        if end == start:
            raise ValueError(f"end: expected end != start for linear fog, got start = end = {end!r}")
        f = (end - c) / (end - start)
    elif mode in ("exp", "exp2"):
        density = number(density, "density", low=0.0)
        dc = density * c
        f = np.exp(-dc) if mode == "exp" else np.exp(-(dc * dc))
    else:
        raise choice_error("mode", mode, FOG_MODES)
    return np.clip(f, 0.0, 1.0).astype(c.dtype, copy=False)


def apply_fog(
    rgba: np.ndarray,
    distance: np.ndarray,
    fog_color: np.ndarray | tuple[float, float, float],
    mode: FogMode = "exp",
    *,
    density: float = 1.0,
    start: float = 0.0,
    end: float = 1.0,
) -> np.ndarray:
    """Blend premultiplied RGBA towards the fog colour by eye distance (OpenGL §3.10).

    ``rgb' = f·rgb + (1 − f)·α·C_f``, ``α' = α`` with ``f = fog_factor(distance, ...)``.

    Args:
        rgba: (..., 4) premultiplied, linear-light RGBA.
        distance: eye distances, shape ``rgba.shape[:-1]``.
        fog_color: linear RGB fog colour ``C_f`` (3 values).
        mode: fog mode, see :func:`fog_factor`.
        density: exponential density, see :func:`fog_factor`.
        start: linear start distance, see :func:`fog_factor`.
        end: linear end distance, see :func:`fog_factor`.

    Returns:
        (..., 4) fogged premultiplied RGBA in the dtype of ``rgba``.
    """
    img = real_array(rgba, "rgba", last_axis=4)
    d = real_array(distance, "distance")
    if d.shape != img.shape[:-1]:
        raise ValueError(
            f"distance: expected shape {img.shape[:-1]} (rgba without its last axis), got {d.shape}"
        )
    cf = real_array(fog_color, "fog_color")
    if cf.shape != (3,):
        raise ValueError(f"fog_color: expected 3 values (linear RGB), got shape {cf.shape}")
    f = fog_factor(d, mode, density=density, start=start, end=end)[..., None].astype(img.dtype)
    out = img.copy()
    alpha = img[..., 3:4]
    out[..., :3] = f * img[..., :3] + (1.0 - f) * alpha * cf.astype(img.dtype)
    return out
