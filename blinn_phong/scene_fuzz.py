"""Random everyday scenes at the sizes people render, for finding frames the renderer cannot make.

A user's first scenes are not the frame-filling close-ups a feature is built with: they are a
few objects standing on a floor under open sky, seen from eye height at 640×480 or 1080p, with
much of the frame empty. Such frames split into bands and tiles that hold no fragment, no
shadowed light, no transparent fragment or no textured pixel, which is where renderers break.

:func:`fuzz_case` builds one seeded case: an :func:`everyday_scene` (spheres, boxes and panes on
a floor, some partly off-screen; opaque, transparent and textured materials; one to three
lights of every type, some behind the camera, some inside an object; fog sometimes), a random
camera (some looking at mostly sky, some at mostly floor), a frame size from 1×1 through
1920×1080 (odd, prime, tall and wide among them), a sample count of 1, 4, 9, 16 or 36, and a
shadow and transparency method (the planner's or one forced). :func:`check_case` renders it
with the compiled engine at full size, checks that every pixel is finite and within the
premultiplied range, and renders a downscaled copy with both engines to compare them
(:data:`ENGINE_TOLERANCE`).

The test suite runs a fixed set of seeds (``tests/blinn_phong/test_scene_fuzz.py``);
``python -m benchmarks.scene_fuzz N`` runs a longer sweep and writes how many frames rendered.
This module is separate from the planner's fuzzer (:mod:`benchmarks.planner_fuzz`), which checks
the planner's error promise on small frames.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

import blinn_phong as bp
from blinn_phong.model.primitives import box, grid_plane, uv_sphere
from blinn_phong.planning.frame_plan import SHADOW_CHOICES, TRANSPARENCY_CHOICES

__all__ = [
    "ENGINE_TOLERANCE",
    "FRAME_SIZES",
    "SAMPLE_COUNTS",
    "CaseReport",
    "FuzzCase",
    "check_case",
    "downscaled_size",
    "everyday_scene",
    "fuzz_case",
]

#: Frame sizes drawn from: the sizes people render, degenerate ones, odd, prime, tall and wide.
FRAME_SIZES: tuple[tuple[int, int], ...] = (
    (1, 1),
    (2, 3),
    (7, 1),
    (1, 13),
    (64, 48),
    (97, 61),
    (160, 90),
    (180, 640),
    (320, 180),
    (320, 240),
    (401, 227),
    (640, 480),
    (800, 600),
    (1000, 50),
    (1024, 576),
    (1279, 719),
    (1280, 720),
    (1920, 1080),
)
#: Samples per pixel (k² on a k×k grid): the add-on's and README's 2×2 up to 6×6.
SAMPLE_COUNTS: tuple[int, ...] = (1, 4, 9, 16, 36)
#: Largest pixel count of the downscaled copy both engines render.
COMPARE_PIXELS = 64 * 48
#: Largest difference allowed between the engines' premultiplied RGBA on the downscaled copy.
#: The engines compute the same fragments; lighting sums run in another order (float64, then
#: float32 output), so they agree to float32 rounding of values below a few units: 1e-5.
#: Samples where two surfaces tie in depth to the last bits, or a shadow-map look-up lands on a
#: texel boundary, may resolve differently; :data:`ENGINE_PIXEL_SHARE` bounds how many pixels.
ENGINE_TOLERANCE = 1e-5
#: Share of the compared pixels allowed to differ by more than :data:`ENGINE_TOLERANCE`
#: (depth ties and texel-boundary look-ups; each such pixel is a whole-sample decision).
ENGINE_PIXEL_SHARE = 0.01


@dataclass(frozen=True)
class FuzzCase:
    """One seeded frame: a scene, its size and the render options.

    Attributes:
        seed: the seed it was built from.
        scene: the :class:`blinn_phong.Scene`.
        width: frame width in pixels.
        height: frame height in pixels.
        samples: samples per pixel (a square).
        options: keyword arguments for :func:`blinn_phong.frame.render` (``shadows``,
            ``transparency``, ``fog``).
        notes: what the case holds (for messages).
    """

    seed: int
    scene: bp.Scene
    width: int
    height: int
    samples: int
    options: dict[str, object] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line: seed, size, samples, options and what the scene holds."""
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.items() if k != "fog")
        fog = " fog" if self.options.get("fog") is not None else ""
        return (
            f"seed {self.seed}: {self.width}×{self.height} samples={self.samples} {opts}{fog}; "
            + "; ".join(self.notes)
        )


@dataclass(frozen=True)
class CaseReport:
    """What :func:`check_case` found.

    Attributes:
        case: the case.
        seconds: wall time of the full-size render.
        plan: the plan's reasons.
        compared: ``(width, height)`` of the engine comparison, or None when skipped.
        engine_difference: largest |compiled − numpy| over the compared RGBA.
        differing_pixels: compared pixels above :data:`ENGINE_TOLERANCE`.
    """

    case: FuzzCase
    seconds: float
    plan: tuple[str, ...]
    compared: tuple[int, int] | None
    engine_difference: float
    differing_pixels: int


def _checker(rng: np.random.Generator) -> bp.Texture:
    """A small straight-alpha checker texture (sometimes with transparent squares)."""
    n = int(rng.integers(2, 9))
    cells = (np.add.outer(np.arange(n), np.arange(n)) % 2).astype(np.float64)
    a, b = rng.uniform(0.1, 1.0, 3), rng.uniform(0.0, 0.6, 3)
    rgb = cells[..., None] * a + (1 - cells[..., None]) * b
    alpha = np.ones((n, n, 1))
    if rng.random() < 0.3:
        alpha[..., 0] = np.where(cells > 0, 1.0, rng.uniform(0.0, 0.6))
    image = np.concatenate([rgb, alpha], axis=-1) * np.concatenate([alpha.repeat(3, -1), alpha], -1)
    return bp.Texture(
        image.astype(np.float32),
        interpolation=str(rng.choice(["closest", "linear"])),
        extension=str(rng.choice(["repeat", "extend", "clip"])),
    )


def _material(rng: np.random.Generator, kind: str) -> bp.Material:
    colour = tuple(float(v) for v in rng.uniform(0.1, 0.9, 3))
    kw: dict[str, object] = {
        "ambient": colour,
        "diffuse": colour,
        "specular": (float(rng.uniform(0.0, 0.8)),) * 3,
        "shininess": float(rng.uniform(1.0, 120.0)),
    }
    if rng.random() < 0.1:
        kw["emission"] = tuple(float(v) for v in rng.uniform(0.0, 0.4, 3))
    if kind == "transparent":
        kw["opacity"] = float(rng.uniform(0.15, 0.9))
        kw["transparency_model"] = str(rng.choice(["partial_occlusion", "emission", "absorption"]))
        if rng.random() < 0.2:
            t_max = float(rng.uniform(0.3, 0.9))
            kw["kay_greenberg"] = (float(rng.uniform(0.0, t_max)), t_max, float(rng.uniform(0.5, 4.0)))
        if rng.random() < 0.2:
            kw["specular_washout"] = True
    elif kind == "textured":
        kw["base_color_texture"] = _checker(rng)
        if rng.random() < 0.3:
            kw["alpha_clip"] = float(rng.uniform(0.2, 0.8))
    return bp.Material(**kw)  # type: ignore[arg-type]


def _planar_uv(positions: np.ndarray, axes: tuple[int, int], repeat: float) -> np.ndarray:
    """Texture coordinates projected along the third axis, scaled to ``repeat`` tiles."""
    p = positions[:, axes]
    lo, hi = p.min(axis=0), p.max(axis=0)
    return (p - lo) / np.where(hi > lo, hi - lo, 1.0) * repeat


def _translate(x: float, y: float, z: float, yaw: float = 0.0, scale: float = 1.0) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array(
        [[c * scale, 0, s * scale, x], [0, scale, 0, y], [-s * scale, 0, c * scale, z], [0, 0, 0, 1]], float
    )


def everyday_scene(rng: np.random.Generator, aspect: float = 4 / 3) -> tuple[bp.Scene, list[str]]:
    """A random everyday scene: objects standing on a floor under open sky, with a camera.

    Args:
        rng: the random generator (seeded by the caller).
        aspect: the camera's width / height (the frame's).

    Returns:
        ``(scene, notes)``: the scene (world units are metres, +Y up, the floor at y = 0) and a
        short description of what it holds.
    """
    notes: list[str] = []
    meshes: list[bp.Mesh] = []
    centres: list[np.ndarray] = []
    floor_size = float(rng.choice([4.0, 12.0, 60.0]))
    cells = int(rng.choice([1, 1, 4, 16]))
    fp, ft, fn = grid_plane(cells, cells, size=(floor_size, floor_size))
    lay_flat = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)  # z = 0 → y = 0
    floor_kind = str(rng.choice(["opaque", "opaque", "textured"]))
    meshes.append(
        bp.Mesh(fp, ft, fn, transform=lay_flat, material=_material(rng, floor_kind),
                uv=_planar_uv(fp, (0, 1), float(rng.uniform(1, 8))))
    )  # fmt: skip
    notes.append(f"floor {floor_size:g} m {floor_kind}")
    for _ in range(int(rng.integers(1, 5))):
        shape = str(rng.choice(["sphere", "box", "pane"]))
        kind = str(rng.choice(["opaque", "opaque", "transparent", "textured"]))
        size = float(rng.uniform(0.2, 1.5))
        x, z = (float(v) for v in rng.uniform(-4.0, 4.0, 2))
        yaw = float(rng.uniform(0, 2 * math.pi))
        if shape == "sphere":
            seg = int(rng.integers(8, 48))
            p, t, n = uv_sphere(seg, max(2, seg // 2), size)
            y = size * float(rng.choice([1.0, 1.0, 0.6, 2.5]))  # standing, sunk, floating
            uv = _planar_uv(p, (0, 1), 2.0)
        elif shape == "box":
            half = rng.uniform(0.3, 1.0, 3) * size
            p, t, n = box(tuple(half))
            # standing 1 mm above the floor: a bottom face exactly on the floor would z-fight with
            # it, and which of two coplanar surfaces wins a sample is left to rounding (the engines
            # round differently), as in OpenGL
            y = float(half[1]) + 1e-3
            # each face unwrapped onto the whole image, as a default cube's UVs: a face never lies
            # on the Clip extension's edge u or v = 0 or 1, only its border does
            uv = np.tile([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (6, 1))
        else:  # an upright pane (a sign, a window): a thin two-sided quad
            w, h = float(rng.uniform(0.5, 2.5)), float(rng.uniform(0.5, 2.0))
            p = np.array([[-w, 0, 0], [w, 0, 0], [w, 2 * h, 0], [-w, 2 * h, 0]], float) / 2
            t = np.array([[0, 1, 2], [0, 2, 3]])
            n = np.tile([0.0, 0.0, 1.0], (4, 1))
            y = 0.0
            uv = _planar_uv(p, (0, 1), 1.0)
        meshes.append(
            bp.Mesh(p, t, n, transform=_translate(x, y, z, yaw), material=_material(rng, kind), uv=uv)
        )
        centres.append(np.array([x, y, z]))
        notes.append(f"{kind} {shape} at ({x:.1f}, {y:.1f}, {z:.1f})")

    eye = np.array([rng.uniform(-8, 8), rng.uniform(0.3, 5.0), rng.uniform(3, 10)])
    look = str(rng.choice(["objects", "sky", "floor", "objects"]))
    if look == "sky":
        target = eye + np.array([rng.uniform(-1, 1), rng.uniform(0.2, 1.5), -1.0])
    elif look == "floor":
        target = np.array([eye[0] + rng.uniform(-1, 1), 0.0, eye[2] - rng.uniform(0.2, 2.0)])
    else:
        target = centres[int(rng.integers(len(centres)))] + rng.uniform(-1, 1, 3)
    notes.append(f"camera looking at {look}")

    lights: list[object] = []
    for _ in range(int(rng.integers(1, 4))):
        kind = str(rng.choice(["directional", "directional", "point", "spot", "ambient"]))
        colour = tuple(float(v) for v in rng.uniform(0.3, 1.0, 3))
        where = str(rng.choice(["above", "above", "behind_camera", "inside_object"]))
        if where == "behind_camera":
            position = eye + (eye - target) / max(np.linalg.norm(eye - target), 1e-9) * rng.uniform(0.5, 3)
        elif where == "inside_object":
            position = centres[int(rng.integers(len(centres)))] + rng.uniform(-0.05, 0.05, 3)
        else:
            position = np.array([rng.uniform(-6, 6), rng.uniform(1.5, 8), rng.uniform(-6, 6)])
        position = tuple(float(v) for v in position)
        if kind == "directional":
            direction = (float(rng.uniform(-1, 1)), float(-rng.uniform(0.1, 1.0)), float(rng.uniform(-1, 1)))
            lights.append(bp.DirectionalLight(direction, diffuse=colour, specular=colour))
            notes.append("sun")
        elif kind == "point":
            falloff = {"linear": float(rng.uniform(0, 0.3)), "quadratic": float(rng.uniform(0, 0.1))}
            lights.append(bp.PointLight(position, diffuse=colour, specular=colour, **falloff))
            notes.append(f"point light {where}")
        elif kind == "spot":
            aim = centres[int(rng.integers(len(centres)))] - np.array(position)
            if not np.linalg.norm(aim) > 1e-6:
                aim = np.array([0.0, -1.0, 0.0])
            cone = (float(rng.uniform(10, 80)), float(rng.uniform(0, 40)))  # cutoff, exponent
            aim_at = tuple(float(v) for v in aim)
            lights.append(bp.SpotLight(position, aim_at, *cone, diffuse=colour, specular=colour))
            notes.append(f"spot light {where}")
        else:
            lights.append(bp.AmbientLight(tuple(0.3 * c for c in colour)))
            notes.append("ambient light")
    fov, near, far = (
        float(rng.uniform(25, 90)),
        float(rng.choice([0.05, 0.1, 0.5])),
        float(rng.choice([30, 100, 500])),
    )
    camera = bp.Camera.perspective(fov, aspect, near, far, view=bp.look_at(tuple(eye), tuple(target)))
    two_sided = bool(rng.random() < 0.5)
    scene = bp.Scene(meshes, lights, camera, light_model=bp.LightModel(two_sided=two_sided))
    return scene, notes


def fuzz_case(seed: int, *, max_samples: int | None = None) -> FuzzCase:
    """The seeded case ``seed``: an everyday scene, a frame size, samples and methods.

    Args:
        seed: any non-negative integer; the same seed always gives the same case.
        max_samples: if given, the sample count is lowered until ``width × height × samples``
            is at most this (the test suite keeps its frames small enough for its time budget).

    Returns:
        The :class:`FuzzCase`.
    """
    rng = np.random.default_rng([seed, 24])
    width, height = FRAME_SIZES[int(rng.integers(len(FRAME_SIZES)))]
    samples = int(rng.choice(SAMPLE_COUNTS))
    if max_samples is not None:
        while samples > 1 and width * height * samples > max_samples:
            samples = int(round(math.sqrt(samples)) - 1) ** 2
    scene, notes = everyday_scene(rng, width / height)
    options: dict[str, object] = {}
    shadow = str(rng.choice(["auto", "auto", *SHADOW_CHOICES]))
    if shadow == "planar":  # forced projected shadows need the receiver: the floor, y = 0
        options["shadows"] = bp.ShadowOptions(method="planar", plane=(0.0, 1.0, 0.0, 0.0))
    elif shadow == "soft":
        options["shadows"] = bp.ShadowOptions(
            method="soft", radius=float(rng.uniform(0.02, 0.5)), samples=int(rng.choice([4, 9, 16]))
        )
    elif shadow == "shadow_map" and rng.random() < 0.5:
        options["shadows"] = bp.ShadowOptions(
            method="shadow_map", resolution=int(rng.choice([64, 512, 2048])),
            kernel=str(rng.choice(["nearest", "bilinear", "box3", "box5", "box7"])),
        )  # fmt: skip
    elif shadow != "auto":
        options["shadows"] = shadow
    if rng.random() < 0.2:
        options["tolerance"] = float(rng.choice([1.0, 4.0, 16.0]))
    if rng.random() < 0.3:
        options["shading"] = str(rng.choice(["flat", "gouraud", "phong"]))
    transparency = str(rng.choice(["auto", "auto", *TRANSPARENCY_CHOICES]))
    if transparency != "auto":
        options["transparency"] = transparency
    if rng.random() < 0.25:
        options["fog"] = bp.Fog(
            mode=str(rng.choice(["linear", "exp", "exp2"])),
            color=tuple(float(v) for v in rng.uniform(0.3, 0.9, 3)),
            density=float(rng.uniform(0.01, 0.2)),
            start=1.0,
            end=float(rng.uniform(10, 60)),
        )
    return FuzzCase(seed, scene, width, height, samples, options, tuple(notes))


def downscaled_size(width: int, height: int, pixels: int = COMPARE_PIXELS) -> tuple[int, int]:
    """The frame size with the same aspect (to a pixel) and at most ``pixels`` pixels."""
    scale = min(1.0, math.sqrt(pixels / (width * height)))
    return max(1, math.floor(width * scale)), max(1, math.floor(height * scale))


def _with_aspect(scene: bp.Scene, width: int, height: int) -> bp.Scene:
    """The scene with its camera's aspect set for a ``width × height`` frame."""
    p = scene.camera.projection.copy()
    p[0, 0] = p[1, 1] * height / width
    return bp.Scene(scene.meshes, scene.lights, bp.Camera(scene.camera.view, p, "perspective"),
                    light_model=scene.light_model)  # fmt: skip


def _check_image(result: bp.RenderResult, width: int, height: int, what: str) -> None:
    rgba = result.rgba
    if rgba.shape != (height, width, 4) or rgba.dtype != np.float32:
        raise AssertionError(
            f"{what}: rgba has shape {rgba.shape} {rgba.dtype}, expected ({height}, {width}, 4)"
        )
    for name, array in [
        ("rgba", rgba),
        ("depth", result.depth),
        ("normal", result.normal),
        *result.passes.items(),
    ]:
        if not np.isfinite(array).all():
            raise AssertionError(
                f"{what}: {name} has {int(np.count_nonzero(~np.isfinite(array)))} non-finite values"
            )
    alpha = rgba[..., 3]
    if alpha.min() < 0 or alpha.max() > 1 + 1e-6 or rgba[..., :3].min() < 0:
        raise AssertionError(
            f"{what}: rgba outside the premultiplied range: alpha in [{alpha.min()}, {alpha.max()}], "
            f"colour min {rgba[..., :3].min()}"
        )


def check_case(case: FuzzCase, *, compare: bool = True) -> CaseReport:
    """Render ``case`` at full size (compiled engine) and, with ``compare``, both engines downscaled.

    Raises:
        AssertionError: a non-finite value or an out-of-range pixel, or the engines differ by more
            than :data:`ENGINE_TOLERANCE` on more than :data:`ENGINE_PIXEL_SHARE` of the pixels;
            the message holds :meth:`FuzzCase.describe`.
        Exception: whatever the renderer raised, with the case noted on it.
    """
    t = time.perf_counter()
    try:
        result = bp.render(case.scene, case.width, case.height, samples=case.samples, progress=False,
                           **case.options)  # type: ignore[arg-type]  # fmt: skip
        seconds = time.perf_counter() - t
        _check_image(result, case.width, case.height, case.describe())
        compared, difference, differing = None, 0.0, 0
        if compare:
            w, h = downscaled_size(case.width, case.height)
            small = _with_aspect(case.scene, w, h)
            kw = dict(samples=min(case.samples, 9), progress=False, **case.options)
            fast = bp.render(small, w, h, engine="numba", **kw)  # type: ignore[arg-type]
            ref = bp.render(small, w, h, engine="numpy", **kw)  # type: ignore[arg-type]
            _check_image(fast, w, h, case.describe() + " (compiled, downscaled)")
            _check_image(ref, w, h, case.describe() + " (numpy, downscaled)")
            delta = np.abs(fast.rgba.astype(np.float64) - ref.rgba).max(axis=-1)
            compared, difference = (w, h), float(delta.max())
            differing = int(np.count_nonzero(delta > ENGINE_TOLERANCE))
            if differing > ENGINE_PIXEL_SHARE * w * h:
                raise AssertionError(
                    f"{case.describe()}: the engines differ on {differing} of {w * h} pixels at {w}×{h} "
                    f"(largest {difference:.3g}); plans {fast.plan.reasons()} / {ref.plan.reasons()}"
                )
    except Exception as exc:
        exc.add_note(f"scene fuzz case: {case.describe()}")
        raise
    plan = tuple(result.plan.reasons()) if result.plan is not None else ()
    return CaseReport(case, seconds, plan, compared, difference, differing)
