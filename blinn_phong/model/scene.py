"""Scene description: meshes, materials, lights, camera, light model.

Conventions (the same as OpenGL's, so a scene can be handed to a real OpenGL
implementation unchanged):

* World space is right-handed. The camera's view matrix maps world to eye space,
  where the eye sits at the origin looking down -Z with +Y up; the projection maps
  eye space to clip space (OpenGL 2.1 spec §2.11, ``gluPerspective``/``glOrtho``).
* Matrices are 4×4 numpy arrays acting on column vectors (``clip = P @ V @ M @ p``),
  i.e. the transpose of what ``glLoadMatrixf`` reads from a C array.
* Colours are linear-light RGB triples, non-negative, unbounded above.
* Light positions and directions are given in world space; the renderer moves them
  to eye space with the view matrix, as ``glLight`` does with the modelview current
  at the call.

OpenGL equivalents (what ``gl_compat=True`` and the Mesa tests hand to OpenGL 2.1):

=======================================  ===============================================
here                                     OpenGL 2.1 fixed function
=======================================  ===============================================
``DirectionalLight(direction=d)``        ``GL_POSITION = (−d, 0)``: GL stores the vector
                                         *towards* the light; ``d`` is the direction the
                                         light travels
``PointLight(position=p)``               ``GL_POSITION = (p, 1)``
``SpotLight(direction=s)``               ``GL_SPOT_DIRECTION = s`` (same sense in both)
attenuation distance ``d``               eye-space distance, as GL (§2.14.1 ``‖VP_pli‖``)
``LightModel(local_viewer=True)``        ``GL_LIGHT_MODEL_LOCAL_VIEWER = GL_TRUE``; GL's
  (the default here)                     default is ``GL_FALSE``: pass
                                         ``local_viewer=False`` for GL's default
``LightModel(specular="blinn")``         the only GL form; ``"phong"`` has no fixed-
                                         function equivalent and ``gl_compat`` refuses it
``LightModel(two_sided=...)``            ``GL_LIGHT_MODEL_TWO_SIDE``
``LightModel(separate_specular=...)``    ``GL_LIGHT_MODEL_COLOR_CONTROL =
                                         GL_SEPARATE_SPECULAR_COLOR``
``Scene(ambient=a)``                     ``GL_LIGHT_MODEL_AMBIENT = (a, 1)`` (default 0.2)
``Material`` fields                      ``glMaterial`` (shininess in [0, 128] under
                                         ``gl_compat``)
``Mesh`` drawn in order                  ``glDepthFunc(GL_LESS)``: ties keep the earlier
=======================================  ===============================================

Every class validates on construction and raises ``ValueError``/``TypeError``
naming the field, the expectation and the value received.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from blinn_phong._checks import check_frame_size, choice_error, colour3, float_array, number
from blinn_phong.model.lights import LIGHT_TYPES, AmbientLight, Colour, Light
from blinn_phong.model.texture import Texture
from blinn_phong.model.transforms import orthographic_matrix, perspective_matrix

__all__ = [
    "Camera",
    "LightLink",
    "LightModel",
    "Material",
    "Mesh",
    "Scene",
    "prepare_render_inputs",
]

Shading = Literal["flat", "gouraud", "phong"]
SHADINGS: tuple[str, ...] = ("flat", "gouraud", "phong")
TransparencyModel = Literal["partial_occlusion", "emission", "absorption"]
TRANSPARENCY_MODELS: tuple[str, ...] = ("partial_occlusion", "emission", "absorption")


# --------------------------------------------------------------------------- material


@dataclass(frozen=True)
class Material:
    """Surface reflectances of the lighting equation (OpenGL ``glMaterial`` names).

    Attributes:
        ambient: ``a_cm``, reflectance for ambient light (linear RGB).
        diffuse: ``d_cm``, Lambertian reflectance (linear RGB).
        specular: ``s_cm``, specular reflectance (linear RGB).
        emission: ``e_cm``, emitted radiance added unlit (linear RGB).
        shininess: ``s_rm``, the specular exponent, >= 0. OpenGL limits it to
            [0, 128]; the renderer accepts larger values outside the GL preset.
        opacity: alpha of the surface in [0, 1] (the alpha of ``d_cm`` in OpenGL).
        transparency_model: how a transparent surface (``opacity < 1`` or
            ``kay_greenberg`` set) of lit colour ``c`` and opacity ``α`` combines with what
            lies behind it; each is the fragment ``src over`` the background
            (:func:`blinn_phong.effects.transparency.transparent_fragment`):

            * ``"partial_occlusion"`` (default) — covers the fraction α:
              premultiplied ``(α·c, α)``, i.e. ``α·c + (1 − α)·behind`` (Porter & Duff 1984);
            * ``"emission"`` — only adds light, hides nothing: ``(α·c, 0)``, i.e.
              ``α·c + behind`` (α scales the glow);
            * ``"absorption"`` — a grey filter of transmittance ``T = 1 − α`` plus the
              light the surface reflects itself: ``(c, α)``, i.e. ``c + T·behind``.
        kay_greenberg: ``(t_min, t_max, power)`` for Kay–Greenberg transparency (Kay &
            Greenberg 1979): the opacity becomes ``1 − t`` with
            ``t = t_min + (t_max − t_min)·[1 − (1 − |N_z|)^power]`` from the eye-space
            normal, replacing ``opacity``; t values in [0, 1], power > 0. None: constant opacity.
        specular_washout: highlights wash out transparency: the opacity becomes
            ``min(1, α + specular luminance)`` (``opaque fraction = (1 − t) + specular``).
        base_color_texture: a :class:`~blinn_phong.model.texture.Texture` modulating the surface
            (OpenGL ``GL_MODULATE`` with ``GL_SEPARATE_SPECULAR_COLOR``): the fragment colour is
            ``(emission + ambient + diffuse terms) × texel RGB + specular`` (texel RGB straight,
            linear) and its opacity ``opacity × texel alpha``. Looked up at the mesh's
            perspective-correct interpolated ``uv`` (the mesh must have ``uv``). Under
            ``kay_greenberg`` the texture's alpha is not used (the opacity comes from the normal).
        alpha_clip: threshold in [0, 1] or None: the fragment's opacity (after the texture)
            becomes 1 where it is ``>= alpha_clip`` and 0 elsewhere (OpenGL's
            ``glAlphaFunc(GL_GEQUAL, alpha_clip)``; Blender EEVEE's *Alpha Clip*): leaves, decals.

    Defaults are OpenGL's (spec §2.14.1 table 2.11 — ambient 0.2, diffuse 0.8,
    specular 0, emission 0, shininess 0). The transparency fields only matter to
    :func:`blinn_phong.frame.render` when it resolves transparency (not under ``gl_compat``).
    """

    ambient: Colour = (0.2, 0.2, 0.2)
    diffuse: Colour = (0.8, 0.8, 0.8)
    specular: Colour = (0.0, 0.0, 0.0)
    emission: Colour = (0.0, 0.0, 0.0)
    shininess: float = 0.0
    opacity: float = 1.0
    transparency_model: TransparencyModel = "partial_occlusion"
    kay_greenberg: tuple[float, float, float] | None = None
    specular_washout: bool = False
    base_color_texture: Texture | None = None
    alpha_clip: float | None = None

    def __post_init__(self) -> None:
        if self.base_color_texture is not None and not isinstance(self.base_color_texture, Texture):
            raise TypeError(
                "Material.base_color_texture: expected a blinn_phong.model.texture.Texture or None, "
                f"got {type(self.base_color_texture).__name__}"
            )
        if self.alpha_clip is not None:
            clip = number(self.alpha_clip, "Material.alpha_clip", low=0.0, high=1.0)
            object.__setattr__(self, "alpha_clip", clip)
            if self.kay_greenberg is not None:
                raise ValueError("Material.alpha_clip: cannot be combined with kay_greenberg (set one)")
        for name in ("ambient", "diffuse", "specular", "emission"):
            object.__setattr__(self, name, colour3(getattr(self, name), f"Material.{name}"))
        object.__setattr__(self, "shininess", number(self.shininess, "Material.shininess", low=0.0))
        object.__setattr__(self, "opacity", number(self.opacity, "Material.opacity", low=0.0, high=1.0))
        if self.transparency_model not in TRANSPARENCY_MODELS:
            raise choice_error("Material.transparency_model", self.transparency_model, TRANSPARENCY_MODELS)
        if self.kay_greenberg is not None:
            values = tuple(self.kay_greenberg) if isinstance(self.kay_greenberg, tuple | list) else ()
            if len(values) != 3:
                raise ValueError(
                    "Material.kay_greenberg: expected (t_min, t_max, power) or None, "
                    f"got {self.kay_greenberg!r}"
                )
            t_min = number(values[0], "Material.kay_greenberg t_min", low=0.0, high=1.0)
            t_max = number(values[1], "Material.kay_greenberg t_max", low=0.0, high=1.0)
            power = number(values[2], "Material.kay_greenberg power", low=0.0, low_open=True)
            object.__setattr__(self, "kay_greenberg", (t_min, t_max, power))
        if not isinstance(self.specular_washout, bool):
            raise TypeError(f"Material.specular_washout: expected a bool, got {self.specular_washout!r}")

    @property
    def transparent(self) -> bool:
        """True when light from behind can show through: ``opacity < 1`` or Kay–Greenberg with t > 0."""
        return self.min_opacity < 1.0

    @property
    def min_opacity(self) -> float:
        """The lowest opacity of a fragment of this material (Kay–Greenberg: ``1 − max(t_min, t_max)``)."""
        if self.kay_greenberg is not None:
            return 1.0 - max(self.kay_greenberg[0], self.kay_greenberg[1])
        low = self.opacity
        if self.base_color_texture is not None:
            low *= self.base_color_texture.min_alpha
        if self.alpha_clip is not None:
            return 1.0 if low >= self.alpha_clip else 0.0
        return low

    @property
    def textured(self) -> bool:
        """True when fragments need the texture stage (a base colour texture or an alpha clip)."""
        return self.base_color_texture is not None or self.alpha_clip is not None


@dataclass(frozen=True)
class LightModel:
    """Global switches of the lighting equation (OpenGL ``glLightModel`` plus the specular form).

    Attributes:
        specular: ``"blinn"`` — ``(n·h)^s`` with the half vector (Blinn 1977; the
            OpenGL equation), or ``"phong"`` — ``(r·v)^s`` with the mirror
            reflection of the light direction (Phong 1975). Fixed-function OpenGL
            has no Phong form, so ``render(..., gl_compat=True)`` refuses ``"phong"``.
        local_viewer: True (the default here): the view vector is ``-normalize(p_eye)``
            (the eye at the eye-space origin), correct for a perspective camera;
            False: the viewer is at infinity, ``v = (0, 0, 1)``. OpenGL's
            ``GL_LIGHT_MODEL_LOCAL_VIEWER`` defaults to **False**: to match a GL
            program that never sets it, pass ``local_viewer=False`` (``gl_compat`` does
            not change the field for you). With an orthographic camera the true view
            direction is (0, 0, 1) everywhere, i.e. ``local_viewer=False``.
        two_sided: light back faces with the flipped normal and the mesh's
            ``back_material`` (``GL_LIGHT_MODEL_TWO_SIDE``). When False back faces
            are lit with the front normal, as OpenGL does.
        separate_specular: keep specular apart from the rest until after
            interpolation and per-vertex clamping (``GL_SEPARATE_SPECULAR_COLOR``);
            only changes results in the GL-compatibility preset.
    """

    specular: Literal["blinn", "phong"] = "blinn"
    local_viewer: bool = True
    two_sided: bool = False
    separate_specular: bool = False

    def __post_init__(self) -> None:
        if self.specular not in ("blinn", "phong"):
            raise ValueError(f"LightModel.specular: expected 'blinn' or 'phong', got {self.specular!r}")
        for name in ("local_viewer", "two_sided", "separate_specular"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"LightModel.{name}: expected a bool, got {getattr(self, name)!r}")


# --------------------------------------------------------------------------- mesh

#: The largest coordinate magnitude a mesh may have: float32's maximum, the range of
#: OpenGL vertex data. Beyond it squared lengths and cross products of edges overflow
#: float64 in the normal and distance computations.
MAX_COORDINATE = float(np.finfo(np.float32).max)


def _check_coordinate_range(values: np.ndarray, name: str) -> None:
    """Refuse coordinates whose magnitude exceeds :data:`MAX_COORDINATE` (finite ones only reach here)."""
    if values.size:
        largest = float(np.max(np.abs(values)))
        if largest > MAX_COORDINATE:
            count = int(np.count_nonzero(np.abs(values) > MAX_COORDINATE))
            raise ValueError(
                f"{name}: expected coordinates within ±{MAX_COORDINATE:.4g} (float32's range, what "
                f"OpenGL vertex data can hold); got {count} beyond it, largest magnitude {largest:.4g}"
            )


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh in object space.

    Attributes:
        positions: (V, 3) vertex positions (object space), finite.
        triangles: (T, 3) integer vertex indices, counter-clockwise = front
            (OpenGL ``GL_CCW``); the last index is the provoking vertex for
            GL-compatible flat shading.
        normals: optional (V, 3) per-vertex normals (object space, any length;
            zero-length normals are allowed and light as unlit-by-direction).
            When None, smooth shading uses :func:`blinn_phong.geometry.normals.vertex_normals`
            with ``normal_weighting``.
        transform: 4×4 model matrix (object → world), column-vector convention.
        material: front material.
        back_material: material for back faces under two-sided lighting
            (defaults to ``material``).
        shading: per-mesh shading frequency overriding the render's, or None.
        normal_weighting: ``"area"`` or ``"angle"`` weighting of face normals
            when averaging vertex normals.
        uv: optional (V, 2) per-vertex texture coordinates, finite; ``u`` left → right and
            ``v`` bottom → top of the image (Blender's and OpenGL's convention, see
            :mod:`blinn_phong.model.texture`); interpolated perspective-correctly. Required when
            a material has a ``base_color_texture``. A UV seam needs split vertices.
        casts_shadows: False to leave the mesh out of every shadow computation (it still
            receives shadows and is seen), as Blender's Object › Visibility › Ray Visibility ›
            Shadow. The planner still counts it as a possible occluder, which can only add
            shadow work, never error.
        holdout: True for a holdout surface (Blender's Holdout shader, ``Object.is_holdout``, a
            view layer's collection *Holdout*; Porter & Duff's ``out``): wherever it is the
            nearest opaque surface of a sample the sample is transparent black ``(0, 0, 0, 0)``
            and what lies behind it stays hidden; transparent surfaces in front of it are
            composited over that transparent black. The mesh counts as opaque whatever its
            material's opacity; it still casts shadows as ``casts_shadows`` says.
    """

    positions: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray | None = None
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    material: Material = field(default_factory=Material)
    back_material: Material | None = None
    shading: Shading | None = None
    normal_weighting: Literal["area", "angle"] = "area"
    uv: np.ndarray | None = None
    casts_shadows: bool = True
    holdout: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.casts_shadows, (bool, np.bool_)):
            raise TypeError(f"Mesh.casts_shadows: expected a bool, got {type(self.casts_shadows).__name__}")
        if not isinstance(self.holdout, (bool, np.bool_)):
            raise TypeError(f"Mesh.holdout: expected a bool, got {type(self.holdout).__name__}")
        positions = float_array(self.positions, "Mesh.positions", (None, 3))
        _check_coordinate_range(positions, "Mesh.positions")
        tri = np.asarray(self.triangles)
        if tri.ndim != 2 or tri.shape[1] != 3:
            raise ValueError(f"Mesh.triangles: expected shape (T, 3), got shape {tri.shape}")
        if tri.size and tri.dtype.kind not in "iu":
            raise TypeError(f"Mesh.triangles: expected integer vertex indices, got dtype {tri.dtype}")
        tri = tri.astype(np.int64, copy=False)
        if tri.size and (tri.min() < 0 or tri.max() >= len(positions)):
            bad = int(np.count_nonzero((tri < 0) | (tri >= len(positions))))
            raise ValueError(
                f"Mesh.triangles: indices must lie in [0, {len(positions) - 1}] (V = {len(positions)}); "
                f"got {bad} out of range, range [{int(tri.min())}, {int(tri.max())}]"
            )
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "triangles", tri)
        if self.normals is not None:
            object.__setattr__(
                self, "normals", float_array(self.normals, "Mesh.normals", (len(positions), 3))
            )
        transform = float_array(self.transform, "Mesh.transform", (4, 4))
        _check_coordinate_range(transform, "Mesh.transform")
        if abs(np.linalg.det(transform[:3, :3])) < 1e-300:
            raise ValueError(
                "Mesh.transform: the upper 3×3 must be invertible (normals use its inverse-transpose)"
            )
        if len(positions):
            world = positions @ transform[:3, :3].T + transform[:3, 3]
            _check_coordinate_range(world, "Mesh.positions in world space (transform applied)")
        object.__setattr__(self, "transform", transform)
        if not isinstance(self.material, Material):
            raise TypeError(f"Mesh.material: expected a Material, got {type(self.material).__name__}")
        if self.back_material is not None and not isinstance(self.back_material, Material):
            raise TypeError(
                f"Mesh.back_material: expected a Material or None, got {type(self.back_material).__name__}"
            )
        if self.shading is not None and self.shading not in SHADINGS:
            raise choice_error("Mesh.shading", self.shading, SHADINGS, also="None or ")
        if self.normal_weighting not in ("area", "angle"):
            raise ValueError(
                f"Mesh.normal_weighting: expected 'area' or 'angle', got {self.normal_weighting!r}"
            )
        if self.uv is not None:
            object.__setattr__(self, "uv", float_array(self.uv, "Mesh.uv", (len(positions), 2)))
        for label, mat in (("material", self.material), ("back_material", self.back_material)):
            if mat is not None and mat.base_color_texture is not None and self.uv is None:
                raise ValueError(
                    f"Mesh.uv: required (shape (V, 2) = ({len(positions)}, 2)) because "
                    f"Mesh.{label} has a base_color_texture, got None"
                )


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True, eq=False)
class Camera:
    """A camera as two OpenGL-convention matrices: ``view`` (world → eye) and ``projection`` (eye → clip).

    Build it with :meth:`perspective`, :meth:`orthographic` or directly from matrices.
    ``kind`` records which projection family it is (``"perspective"``,
    ``"orthographic"`` or ``"custom"``); it is informational.
    """

    view: np.ndarray
    projection: np.ndarray
    kind: Literal["perspective", "orthographic", "custom"] = "custom"

    def __post_init__(self) -> None:
        object.__setattr__(self, "view", float_array(self.view, "Camera.view", (4, 4)))
        object.__setattr__(self, "projection", float_array(self.projection, "Camera.projection", (4, 4)))
        if abs(np.linalg.det(self.view[:3, :3])) < 1e-300:
            raise ValueError("Camera.view: the upper 3×3 must be invertible")

    @classmethod
    def perspective(
        cls, fov_y: float, aspect: float, near: float, far: float, *, view: object | None = None
    ) -> Camera:
        """A perspective camera (``gluPerspective``, vertical ``fov_y`` in degrees; ``view`` default I)."""
        return cls(
            np.eye(4) if view is None else view, perspective_matrix(fov_y, aspect, near, far), "perspective"
        )

    @classmethod
    def orthographic(
        cls,
        left: float,
        right: float,
        bottom: float,
        top: float,
        near: float,
        far: float,
        *,
        view: object | None = None,
    ) -> Camera:
        """An orthographic camera (``glOrtho`` bounds in eye units); ``view`` defaults to identity."""
        return cls(
            np.eye(4) if view is None else view,
            orthographic_matrix(left, right, bottom, top, near, far),
            "orthographic",
        )


# --------------------------------------------------------------------------- scene


def _mesh_mask(value: object, name: str, n_meshes: int) -> np.ndarray | None:
    """``value`` as a read-only (n_meshes,) bool array, or None for None."""
    if value is None:
        return None
    mask = np.asarray(value)
    if mask.shape != (n_meshes,) or mask.dtype != np.bool_:
        raise ValueError(
            f"{name}: expected None or a bool array of shape ({n_meshes},) (one flag per entry of "
            f"Scene.meshes), got dtype {mask.dtype}, shape {mask.shape}"
        )
    mask = mask.copy()
    mask.flags.writeable = False
    return mask


@dataclass(frozen=True, eq=False)
class LightLink:
    """Light and shadow linking of one light (Blender 4.0+ ``Object.light_linking``).

    Attributes:
        receivers: None (every mesh receives the light) or an (M,) bool array over
            ``Scene.meshes``: the meshes the light lights. Elsewhere its diffuse and specular
            terms are 0, as if it were shadowed there (its visibility is 0).
        blockers: None (every mesh with ``casts_shadows`` may shadow it) or an (M,) bool array:
            the only meshes that cast its shadows (each also needs ``casts_shadows``), for
            every shadow method.

    ``LightLink()`` (both None) links nothing. The masks are checked against the scene by
    :class:`Scene` and stored read-only.
    """

    receivers: np.ndarray | None = None
    blockers: np.ndarray | None = None

    @property
    def linked(self) -> bool:
        """True when the light has a receiver or a blocker mask."""
        return self.receivers is not None or self.blockers is not None


@dataclass(frozen=True, eq=False)
class Scene:
    """Everything a render needs.

    Attributes:
        meshes: the meshes, drawn in order (ties in depth go to the earlier one,
            as OpenGL's ``GL_LESS`` does); a single :class:`Mesh` is accepted. A mesh
            without vertices or triangles (Blender scenes have them) renders as nothing.
        lights: any mix of the four light types; a single light is accepted.
        camera: the camera (required).
        ambient: the global ambient ``a_cs`` (``GL_LIGHT_MODEL_AMBIENT``, default 0.2 grey).
        light_model: see :class:`LightModel`.
        light_links: None (no light linking: every light lights every mesh and is blocked by
            every caster, at no cost) or one :class:`LightLink` (or None) per entry of
            ``lights``. An :class:`AmbientLight` cannot be linked, nor can a light with a
            non-zero ``ambient`` colour have receivers (its ambient term is not shadowed, so
            it could not be withheld from the other meshes); lights from Blender have none.
    """

    meshes: tuple[Mesh, ...]
    lights: tuple[Light, ...] = ()
    camera: Camera | None = None
    ambient: Colour = (0.2, 0.2, 0.2)
    light_model: LightModel = field(default_factory=LightModel)
    light_links: tuple[LightLink | None, ...] | None = None

    def __post_init__(self) -> None:
        meshes = _as_tuple(self.meshes, (Mesh,), "Scene.meshes", "a Mesh or a sequence of Meshes")
        for i, m in enumerate(meshes):
            if not isinstance(m, Mesh):
                raise TypeError(f"Scene.meshes[{i}]: expected a Mesh, got {type(m).__name__}")
        lights = _as_tuple(
            self.lights, LIGHT_TYPES, "Scene.lights", "a light or a sequence of lights (may be empty)"
        )
        for i, light in enumerate(lights):
            if not isinstance(light, LIGHT_TYPES):
                raise TypeError(
                    f"Scene.lights[{i}]: expected AmbientLight, DirectionalLight, PointLight or SpotLight, "
                    f"got {type(light).__name__}"
                )
        if self.camera is None:
            raise ValueError("Scene.camera: a scene needs a Camera, got None")
        if not isinstance(self.camera, Camera):
            raise TypeError(f"Scene.camera: expected a Camera, got {type(self.camera).__name__}")
        if not isinstance(self.light_model, LightModel):
            raise TypeError(
                f"Scene.light_model: expected a LightModel, got {type(self.light_model).__name__}"
            )
        object.__setattr__(self, "meshes", meshes)
        object.__setattr__(self, "lights", lights)
        object.__setattr__(self, "ambient", colour3(self.ambient, "Scene.ambient"))
        if self.light_links is not None:
            object.__setattr__(self, "light_links", _check_links(self.light_links, lights, len(meshes)))


def _check_links(links: object, lights: tuple, n_meshes: int) -> tuple[LightLink | None, ...] | None:
    """``Scene.light_links`` checked against the scene; None when no entry links anything."""
    if isinstance(links, LightLink) or isinstance(links, str | bytes) or not hasattr(links, "__iter__"):
        raise TypeError(
            f"Scene.light_links: expected None or a sequence of LightLink/None, got {type(links).__name__}"
        )
    links = tuple(links)  # type: ignore[arg-type]
    if len(links) != len(lights):
        raise ValueError(
            f"Scene.light_links: expected one entry per light ({len(lights)}), got {len(links)}"
        )
    out: list[LightLink | None] = []
    for i, (link, light) in enumerate(zip(links, lights, strict=True)):
        if link is None:
            out.append(None)
            continue
        if not isinstance(link, LightLink):
            raise TypeError(
                f"Scene.light_links[{i}]: expected a LightLink or None, got {type(link).__name__}"
            )
        receivers = _mesh_mask(link.receivers, f"Scene.light_links[{i}].receivers", n_meshes)
        blockers = _mesh_mask(link.blockers, f"Scene.light_links[{i}].blockers", n_meshes)
        if receivers is None and blockers is None:
            out.append(None)
            continue
        if isinstance(light, AmbientLight):
            raise ValueError(f"Scene.light_links[{i}]: an AmbientLight cannot be linked, got {link!r}")
        if receivers is not None and any(light.ambient):
            raise ValueError(
                f"Scene.light_links[{i}].receivers: the light's ambient colour must be 0 to link its "
                f"receivers (the ambient term is not shadowed), got ambient {light.ambient}"
            )
        out.append(LightLink(receivers, blockers))
    return tuple(out) if any(link is not None for link in out) else None


def _as_tuple(value: object, single: tuple[type, ...], name: str, expected: str) -> tuple:
    """``(value,)`` for one item of the ``single`` types, else ``tuple(value)``; TypeError names ``name``."""
    if isinstance(value, single):
        return (value,)
    if isinstance(value, str | bytes) or not hasattr(value, "__iter__"):
        raise TypeError(f"{name}: expected {expected}, got {type(value).__name__}")
    return tuple(value)


def prepare_render_inputs(
    scene: Scene, width: object, height: object, samples: object, gl_compat: bool
) -> Scene:
    """Checks :func:`blinn_phong.frame.render` runs before any work; returns the scene to render.

    * ``width``, ``height``, ``samples``: positive integers whose frame fits in memory
      (:func:`blinn_phong._checks.check_frame_size`: refused up front, the message names
      the three and the bytes needed, instead of a ``MemoryError`` or a long stall).
    * ``gl_compat=True``: the light model must be one fixed-function OpenGL has
      (``specular="blinn"``), as shininess must lie in [0, 128].
    * Meshes without triangles (no vertices, or vertices only) are left out: they cover
      no pixel and cast no shadow. The plan then numbers the remaining meshes.

    Raises:
        TypeError: ``scene`` is not a :class:`Scene`.
        ValueError: as above, naming the argument.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a blinn_phong.Scene, got {type(scene).__name__}")
    check_frame_size(width, height, samples)
    if gl_compat and scene.light_model.specular != "blinn":
        raise ValueError(
            "scene.light_model.specular: OpenGL's fixed-function lighting has only the Blinn half-vector "
            f"form (gl_compat=True needs 'blinn'), got {scene.light_model.specular!r}"
        )
    if all(len(m.triangles) for m in scene.meshes):
        return scene
    kept = np.array([len(m.triangles) > 0 for m in scene.meshes], dtype=bool)
    links = None
    if scene.light_links is not None:
        links = tuple(
            None
            if link is None
            else LightLink(
                None if link.receivers is None else link.receivers[kept],
                None if link.blockers is None else link.blockers[kept],
            )
            for link in scene.light_links
        )
    return Scene(
        tuple(m for m in scene.meshes if len(m.triangles)),
        scene.lights,
        scene.camera,
        scene.ambient,
        scene.light_model,
        links,
    )
