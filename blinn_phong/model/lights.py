"""The light types and what each knows of itself: the light protocol.

Every light that shines from somewhere (:class:`DirectionalLight`, :class:`PointLight`,
:class:`SpotLight`) answers the same questions, so the renderer asks the light rather than its
type:

* :meth:`~PointLight.homogeneous`: its OpenGL ``GL_POSITION`` in world space, ``(p, 1)`` for a
  positional light, ``(−d, 0)`` (the direction towards it) for a directional one;
* :meth:`~PointLight.direction_to`: the unit direction from points towards it and the distance;
* :meth:`~PointLight.eye_space`: its row of the lighting equation's tables in eye space — the
  position or direction moved by the view matrix, the spot direction, cut-off and exponent, and
  the attenuation coefficients ``(kc, kl, kq)`` of ``1 / (kc + kl·d + kq·d²)`` (OpenGL 2.1
  §2.14.1, eq. 2.4; ``(1, 0, 0)`` for a directional light);
* :meth:`~PointLight.shadow_cameras`: the (view, projection) cameras a shadow map of it needs
  around casters within a bounding sphere (Williams 1978).

:class:`AmbientLight` has no position: ``eye_space`` is None and its :attr:`~AmbientLight.radiance`
is summed into the ambient term. A new light type is one class here implementing these, plus its
tests. Conventions: world space, right-handed; 4×4 matrices on column vectors; angles in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np

from blinn_phong._checks import colour3, number, vector3
from blinn_phong._vectors import normalize
from blinn_phong.model.transforms import look_at, orthographic_matrix, perspective_matrix

__all__ = [
    "CUBE_FACES",
    "LIGHT_TYPES",
    "AmbientLight",
    "Colour",
    "DirectionalLight",
    "EyeLight",
    "Light",
    "PointLight",
    "SpotLight",
]

Colour = tuple[float, float, float]

#: Cube-map faces of a point light's shadow map, in order +x, −x, +y, −y, +z, −z: the (axis, sign)
#: of the major axis and the look-at up vector per face (OpenGL 4.6 §8.13 table 8.19).
CUBE_FACES = (
    (0, 1.0, (0.0, -1.0, 0.0)),
    (0, -1.0, (0.0, -1.0, 0.0)),
    (1, 1.0, (0.0, 0.0, 1.0)),
    (1, -1.0, (0.0, 0.0, -1.0)),
    (2, 1.0, (0.0, -1.0, 0.0)),
    (2, -1.0, (0.0, -1.0, 0.0)),
)
#: A spot light's shadow map is one perspective camera up to this cut-off (degrees), else a cube.
SPOT_MAP_CUTOFF = 80.0


class EyeLight(NamedTuple):
    """One light's row of the lighting equation's tables, in eye space.

    Attributes:
        position: (4,) homogeneous position (w = 1) or direction towards the light (w = 0).
        spot_direction: (3,) unit spot axis, zeros for a light without a cone.
        cos_cutoff: cosine of the spot cut-off, −inf without a cone.
        spot_exponent: the spot exponent, 0 without a cone.
        attenuation: ``(kc, kl, kq)`` of ``1 / (kc + kl·d + kq·d²)``, d the eye-space distance.
    """

    position: np.ndarray
    spot_direction: np.ndarray
    cos_cutoff: float
    spot_exponent: float
    attenuation: tuple[float, float, float]


def _up_for(direction: np.ndarray) -> np.ndarray:
    return np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([1.0, 0.0, 0.0])


def _positional_direction_to(position: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    offset = position - np.asarray(points, dtype=np.float64).reshape(-1, 3)
    distance = np.linalg.norm(offset, axis=1)
    return normalize(offset), distance


def _cube_cameras(position: np.ndarray, near: float, far: float) -> list[tuple[np.ndarray, np.ndarray]]:
    proj = perspective_matrix(90.0, 1.0, near, far)
    cameras = []
    for axis, sign, up in CUBE_FACES:
        d = np.zeros(3)
        d[axis] = sign
        cameras.append((look_at(position, position + d, up), proj))
    return cameras


def _near_far(position: np.ndarray, centre: np.ndarray, radius: float) -> tuple[float, float]:
    far = float(np.linalg.norm(centre - position)) + radius
    return max(far * 1e-3, 1e-6), far


def _light_colours(
    cls: str, color: object, intensity: object, ambient: object, diffuse: object, specular: object
) -> tuple[Colour, Colour, Colour]:
    """Resolve 'one colour × intensity' or explicit OpenGL-style ambient/diffuse/specular colours."""
    base = np.asarray(colour3(color, f"{cls}.color")) * number(intensity, f"{cls}.intensity", low=0.0)
    base3 = (float(base[0]), float(base[1]), float(base[2]))
    amb = (0.0, 0.0, 0.0) if ambient is None else colour3(ambient, f"{cls}.ambient")
    dif = base3 if diffuse is None else colour3(diffuse, f"{cls}.diffuse")
    spe = base3 if specular is None else colour3(specular, f"{cls}.specular")
    return amb, dif, spe


def _attenuation(cls: str, constant: object, linear: object, quadratic: object) -> tuple[float, float, float]:
    kc = number(constant, f"{cls}.constant", low=0.0)
    kl = number(linear, f"{cls}.linear", low=0.0)
    kq = number(quadratic, f"{cls}.quadratic", low=0.0)
    if kc == 0.0 and kl == 0.0 and kq == 0.0:
        raise ValueError(f"{cls}: attenuation (constant, linear, quadratic) must not all be 0, got (0, 0, 0)")
    return kc, kl, kq


@dataclass(frozen=True)
class AmbientLight:
    """A uniform ambient light: adds ``a_cm · color · intensity`` everywhere (no direction)."""

    color: Colour = (1.0, 1.0, 1.0)
    intensity: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "color", colour3(self.color, "AmbientLight.color"))
        object.__setattr__(self, "intensity", number(self.intensity, "AmbientLight.intensity", low=0.0))

    @property
    def radiance(self) -> Colour:
        """``color · intensity`` (linear RGB)."""
        c = np.asarray(self.color) * self.intensity
        return (float(c[0]), float(c[1]), float(c[2]))

    #: No position, no direction: nothing to shadow.
    positional: ClassVar[bool] = False
    casts_shadows: ClassVar[bool] = False

    def eye_space(self, view: np.ndarray) -> None:
        """None: an ambient light has no row of its own (its radiance joins the ambient term)."""
        return None


@dataclass(frozen=True, init=False)
class DirectionalLight:
    """A light at infinity shining along ``direction`` (world space; OpenGL position w = 0).

    ``direction`` is the direction the light *travels* (from the light into the scene):
    the default ``(0, 0, -1)`` shines down -Z. OpenGL stores the opposite vector, the
    direction *towards* the light, as ``GL_POSITION = (x, y, z, 0)``; the GL equivalent
    of ``DirectionalLight(direction=d)`` is ``glLightfv(GL_POSITION, (-d, 0))``.

    Colours: either ``color`` × ``intensity`` for diffuse and specular (ambient 0),
    or explicit ``ambient``/``diffuse``/``specular`` as ``glLight`` takes them
    (an explicit value overrides the one derived from ``color``).
    """

    direction: tuple[float, float, float]
    ambient: Colour
    diffuse: Colour
    specular: Colour

    def __init__(
        self,
        direction: object = (0.0, 0.0, -1.0),
        color: object = (1.0, 1.0, 1.0),
        intensity: object = 1.0,
        *,
        ambient: object = None,
        diffuse: object = None,
        specular: object = None,
    ) -> None:
        object.__setattr__(self, "direction", vector3(direction, "DirectionalLight.direction", unit=True))
        a, d, s = _light_colours("DirectionalLight", color, intensity, ambient, diffuse, specular)
        object.__setattr__(self, "ambient", a)
        object.__setattr__(self, "diffuse", d)
        object.__setattr__(self, "specular", s)

    #: At infinity: its rays are parallel and it has no distance or area.
    positional: ClassVar[bool] = False
    casts_shadows: ClassVar[bool] = True

    def homogeneous(self) -> np.ndarray:
        """(4,) ``GL_POSITION = (−direction, 0)``: the direction towards the light, w = 0."""
        return np.r_[-np.asarray(self.direction, dtype=np.float64), 0.0]

    def direction_to(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) unit direction towards the light from each of the (n, 3) points (the same for
        all), and (n,) distance: infinite."""
        n = len(np.asarray(points).reshape(-1, 3))
        towards = -np.asarray(self.direction, dtype=np.float64)
        return np.tile(towards / np.linalg.norm(towards), (n, 1)), np.full(n, np.inf)

    def eye_space(self, view: np.ndarray) -> EyeLight:
        """Its row in eye space: the direction towards it moved by the view's upper 3×3 and
        renormalised (as ``glLight`` with w = 0), no cone, no attenuation."""
        rot = np.asarray(view, dtype=np.float64)[:3, :3]
        towards = normalize(rot @ -np.asarray(self.direction))
        return EyeLight(np.r_[towards, 0.0], np.zeros(3), -np.inf, 0.0, (1.0, 0.0, 0.0))

    def shadow_cameras(self, centre: np.ndarray, radius: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """One orthographic camera looking along the light over the casters' bounding sphere
        (centre, radius > 0): eye at ``centre − 2·radius·direction``, depth range
        [0.5·radius, 3.5·radius]."""
        d = np.asarray(self.direction, dtype=np.float64)
        eye = centre - d * 2 * radius
        view = look_at(eye, centre, _up_for(d))
        return [(view, orthographic_matrix(-radius, radius, -radius, radius, radius * 0.5, radius * 3.5))]


class _Positional:
    """What every light at a point shares (mixed into :class:`PointLight` and :class:`SpotLight`)."""

    position: tuple[float, float, float]

    #: At a point: rays diverge from it; distance attenuates it.
    positional: ClassVar[bool] = True
    casts_shadows: ClassVar[bool] = True

    def homogeneous(self) -> np.ndarray:
        """(4,) ``GL_POSITION = (position, 1)``."""
        return np.r_[np.asarray(self.position, dtype=np.float64), 1.0]

    def direction_to(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) unit direction from each of the (n, 3) points towards the light (zero at the
        light itself), and (n,) world-space distance."""
        return _positional_direction_to(np.asarray(self.position, dtype=np.float64), points)


@dataclass(frozen=True, init=False)
class PointLight(_Positional):
    """A positional light with attenuation ``1 / (kc + kl·d + kq·d²)``.

    ``position`` is given in world space and moved to eye space by the camera's view
    matrix (as ``glLight`` does with the current modelview). ``d`` is the **eye-space**
    distance between the lit point and the light, as in OpenGL (§2.14.1, ``‖VP_pli‖``
    in eye coordinates); it equals the world-space distance only when the view matrix
    is rigid (rotation and translation), and differs under a scaled or sheared view.
    OpenGL equivalent: ``GL_POSITION = (position, 1)``, ``GL_CONSTANT_ATTENUATION`` etc.

    Colours as for :class:`DirectionalLight`. ``constant``, ``linear``,
    ``quadratic`` must be >= 0 and not all zero (OpenGL 2.1 §2.14.1, eq. 2.4).
    """

    position: tuple[float, float, float]
    ambient: Colour
    diffuse: Colour
    specular: Colour
    constant: float
    linear: float
    quadratic: float

    def __init__(
        self,
        position: object = (0.0, 0.0, 1.0),
        color: object = (1.0, 1.0, 1.0),
        intensity: object = 1.0,
        *,
        constant: object = 1.0,
        linear: object = 0.0,
        quadratic: object = 0.0,
        ambient: object = None,
        diffuse: object = None,
        specular: object = None,
    ) -> None:
        object.__setattr__(self, "position", vector3(position, "PointLight.position"))
        a, d, s = _light_colours("PointLight", color, intensity, ambient, diffuse, specular)
        object.__setattr__(self, "ambient", a)
        object.__setattr__(self, "diffuse", d)
        object.__setattr__(self, "specular", s)
        kc, kl, kq = _attenuation("PointLight", constant, linear, quadratic)
        object.__setattr__(self, "constant", kc)
        object.__setattr__(self, "linear", kl)
        object.__setattr__(self, "quadratic", kq)

    @property
    def axis(self) -> None:
        """None: a point light shines in every direction (no cone)."""
        return None

    def eye_space(self, view: np.ndarray) -> EyeLight:
        """Its row in eye space: the position moved by the view (as ``glLight`` with w = 1), no
        cone, its attenuation ``(constant, linear, quadratic)``."""
        position = np.asarray(view, dtype=np.float64) @ np.r_[self.position, 1.0]
        return EyeLight(position, np.zeros(3), -np.inf, 0.0, (self.constant, self.linear, self.quadratic))

    def shadow_cameras(self, centre: np.ndarray, radius: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Six 90° perspective cube faces at the light, in the order of :data:`CUBE_FACES`,
        spanning ``near = 10⁻³·far`` to ``far`` = the distance to the farthest point of the
        casters' bounding sphere (centre, radius)."""
        position = np.asarray(self.position, dtype=np.float64)
        near, far = _near_far(position, centre, radius)
        return _cube_cameras(position, near, far)


@dataclass(frozen=True, init=False)
class SpotLight(_Positional):
    """A positional light restricted to a cone around ``direction`` (world space).

    Inside the cone (angle between the light→point direction and ``direction``
    at most ``cutoff`` degrees) the factor is ``cos(angle)^exponent``; outside it
    is 0 (OpenGL 2.1 §2.14.1). ``cutoff`` is in (0, 90] degrees, ``exponent`` >= 0.
    ``direction`` is where the spot points, the same sense as ``GL_SPOT_DIRECTION``.
    Attenuation (eye-space distance) and colours as for :class:`PointLight`.
    """

    position: tuple[float, float, float]
    direction: tuple[float, float, float]
    cutoff: float
    exponent: float
    ambient: Colour
    diffuse: Colour
    specular: Colour
    constant: float
    linear: float
    quadratic: float

    def __init__(
        self,
        position: object = (0.0, 0.0, 1.0),
        direction: object = (0.0, 0.0, -1.0),
        cutoff: object = 45.0,
        exponent: object = 0.0,
        color: object = (1.0, 1.0, 1.0),
        intensity: object = 1.0,
        *,
        constant: object = 1.0,
        linear: object = 0.0,
        quadratic: object = 0.0,
        ambient: object = None,
        diffuse: object = None,
        specular: object = None,
    ) -> None:
        object.__setattr__(self, "position", vector3(position, "SpotLight.position"))
        object.__setattr__(self, "direction", vector3(direction, "SpotLight.direction", unit=True))
        object.__setattr__(
            self, "cutoff", number(cutoff, "SpotLight.cutoff (degrees)", low=0.0, high=90.0, low_open=True)
        )
        object.__setattr__(self, "exponent", number(exponent, "SpotLight.exponent", low=0.0))
        a, d, s = _light_colours("SpotLight", color, intensity, ambient, diffuse, specular)
        object.__setattr__(self, "ambient", a)
        object.__setattr__(self, "diffuse", d)
        object.__setattr__(self, "specular", s)
        kc, kl, kq = _attenuation("SpotLight", constant, linear, quadratic)
        object.__setattr__(self, "constant", kc)
        object.__setattr__(self, "linear", kl)
        object.__setattr__(self, "quadratic", kq)

    @property
    def axis(self) -> tuple[float, float, float]:
        """The unit direction the cone points along (``direction``)."""
        return self.direction

    def eye_space(self, view: np.ndarray) -> EyeLight:
        """Its row in eye space: the position moved by the view, the spot axis by its upper 3×3
        (renormalised), the cosine of the cut-off, the exponent and the attenuation."""
        view = np.asarray(view, dtype=np.float64)
        position = view @ np.r_[self.position, 1.0]
        axis = normalize(view[:3, :3] @ np.asarray(self.direction))
        return EyeLight(
            position,
            axis,
            np.cos(np.radians(self.cutoff)),
            self.exponent,
            (self.constant, self.linear, self.quadratic),
        )

    def shadow_cameras(self, centre: np.ndarray, radius: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """One perspective camera at the light along its axis, field of view twice the cut-off,
        when the cut-off is at most :data:`SPOT_MAP_CUTOFF`; else the six cube faces of a point
        light. Depth range as :meth:`PointLight.shadow_cameras`."""
        position = np.asarray(self.position, dtype=np.float64)
        near, far = _near_far(position, centre, radius)
        if self.cutoff <= SPOT_MAP_CUTOFF:
            d = np.asarray(self.direction, dtype=np.float64)
            view = look_at(position, position + d, _up_for(d))
            return [(view, perspective_matrix(2 * self.cutoff, 1.0, near, far))]
        return _cube_cameras(position, near, far)


Light = AmbientLight | DirectionalLight | PointLight | SpotLight
LIGHT_TYPES = (AmbientLight, DirectionalLight, PointLight, SpotLight)
