"""The engine's render settings -> ``blinn_phong.frame.render`` (no bpy).

``blinn_phong.frame.render`` plans transparency and shadows (``blinn_phong.planning.planner``), renders the
effects the plan needs (``blinn_phong.planning.frame_plan``) and returns the plan with a reason per decision.
This module only translates the add-on's settings (``addon/options.py``: one ``RenderOptions``
type, declared once) into its arguments ("Auto" = the planner's choice). Without Embree
(``embreex``), ``render`` itself replaces ray-traced and planar shadows by shadow volumes and soft
shadows by shadow maps, and says so in the plan; without numba the numpy kernels run, with a warning.

Outputs follow the project conventions (float32 premultiplied linear RGBA, row 0 at the top).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from blinn_phong import Cryptomatte, Fog, LightGroups, ShadowOptions, render
from blinn_phong.model.lights import AmbientLight
from blinn_phong.model.scene import Scene
from compositing._kernel_cache import compile_clock

from .options import SHADOW_SETTINGS, TRANSPARENCY_SETTINGS, RenderOptions, deep_output_problem

__all__ = [
    "SHADOW_SETTINGS",
    "TRANSPARENCY_SETTINGS",
    "FrameResult",
    "RenderOptions",
    "kernel_engine",
    "render_frame",
    "status_line",
    "warm_kernels",
]


_WARMED: dict[str, float] = {}


def embree_available() -> bool:
    """True when Embree (``embreex``) imports: ray-traced and soft shadows are available."""
    try:
        import embreex  # noqa: F401
    except Exception:
        return False
    return True


def warm_kernels(requested: str = "AUTO") -> float:
    """Load the compiled kernels once per process, before the first frame.

    Renders a one-triangle 4×4 scene with the kernels :func:`kernel_engine` picks. numba compiles
    on first use and caches the machine code on disk (once per user and machine,
    ``compositing/_kernel_cache.py``; inside an installed extension, the extension's user
    directory), so this takes seconds once per machine and milliseconds afterwards. It loads the
    kernels every frame needs; an effect's own kernels load (or compile) inside its first frame —
    :func:`render_frame` reports the compile seconds it waited for in ``seconds["compile"]``.

    Returns:
        Seconds spent, the first time in this process for the compiled kernels; 0.0 otherwise.
    """
    kernels, _warning = kernel_engine(requested)
    if kernels != "numba" or kernels in _WARMED:
        return 0.0
    from blinn_phong.model.lights import DirectionalLight
    from blinn_phong.model.scene import Camera, Mesh
    from blinn_phong.model.transforms import orthographic_matrix

    started = time.perf_counter()
    tiny = Scene(
        meshes=(
            Mesh(
                positions=np.array([[-1.0, -1, -2], [1, -1, -2], [0, 1, -2]]), triangles=np.array([[0, 1, 2]])
            ),
        ),
        lights=(DirectionalLight(direction=(0.0, 0.0, -1.0)),),
        camera=Camera(np.eye(4), orthographic_matrix(-1, 1, -1, 1, 0.5, 4.0), "orthographic"),
    )
    render(tiny, 4, 4, engine="numba", samples=4, shadows="none")
    _WARMED[kernels] = time.perf_counter() - started
    return _WARMED[kernels]


#: Interactive Blender (a UI): a frame whose kernels are not compiled yet renders with numpy while a
#: background process compiles them (:func:`frame_engine`). The engine sets it at register (off in
#: background mode: the batch and headless runs compile in their own process, nothing to freeze).
BACKGROUND_COMPILE = False
_warmup: dict[str, Any] = {}


def frame_engine(requested: str = "AUTO") -> tuple[str, str | None]:
    """The ``RenderOptions.engine`` to render an interactive frame with, and a note for the status line.

    With :data:`BACKGROUND_COMPILE` and the compiled kernels neither loaded in this process nor
    compiled on this machine (:func:`blinn_phong.warmup.is_warm`), the first call starts
    ``python -m blinn_phong.warmup`` in a background process
    (:func:`blinn_phong.warmup.start_background`) and frames render with the numpy engine (the
    same images, slower) until it has exited; then with the compiled kernels, loaded from the
    cache in about a second. Compiling in Blender's own process would hold Python's global
    interpreter lock for minutes, and Blender's interface would freeze. If the background
    process fails, frames compile in this process as before (and the note says why).

    Returns:
        ``(engine, note)``: ``requested`` or ``"NUMPY"``; the note is None when nothing is
        compiling.
    """
    kernels, _warning = kernel_engine(requested)
    if kernels != "numba" or not BACKGROUND_COMPILE or kernels in _WARMED:
        return requested, None
    from blinn_phong import warmup

    process = _warmup.get("process")
    if process is None:
        if warmup.is_warm():
            return requested, None
        process = _warmup["process"] = warmup.start_background()
        _warmup["started"] = time.perf_counter()
    code = process.poll()
    if code is None:
        elapsed = time.perf_counter() - _warmup["started"]
        return "NUMPY", f"kernels compiling in the background ({elapsed:.0f} s): numpy engine meanwhile"
    if code != 0:
        return requested, f"background compile failed (exit {code}): kernels compiled in Blender"
    return requested, None


def status_line(choices: dict[str, object], seconds: float, stats: dict[str, float] | None = None) -> str:
    """The render's one-line status: time, kernels, Embree and the methods the plan chose.

    Example: ``Blinn-Phong 0.42 s (kernels compiled 3.10 s) | numba, Embree | shading phong, 4
    spp | transparency a_buffer | shadows ray_traced, none``.
    """
    compiled = (stats or {}).get("compile")
    head = f"Blinn-Phong {seconds:.2f} s" + (f" (kernels compiled {compiled:.2f} s)" if compiled else "")
    kernels = str(choices.get("engine", "?")) + (", Embree" if choices.get("embree") else ", no Embree")
    if choices.get("warnings"):
        kernels += " (WARNING: fallback)"
    if choices.get("compile_note"):
        kernels += f" ({choices['compile_note']})"
    shadows = choices.get("shadows") or []
    parts = [
        head,
        kernels,
        f"shading {choices.get('shading')}, {choices.get('samples')} spp",
        f"transparency {choices.get('transparency')}",
        "shadows " + (", ".join(str(m) for m in shadows) if shadows else "none (no light)"),
    ]
    if choices.get("fog") not in (None, "NONE"):
        parts.append(f"fog {str(choices['fog']).lower()}")
    return " | ".join(parts)


def kernel_engine(requested: str = "AUTO") -> tuple[str, str | None]:
    """The kernel implementation to run and, when the compiled one cannot load, why.

    Args:
        requested: ``RenderOptions.engine``: ``"AUTO"`` (numba when it imports) or ``"NUMPY"``.

    Returns:
        ``("numba", None)``, ``("numpy", None)`` when numpy was asked for, or
        ``("numpy", warning)`` when numba failed to import (the warning names the error).
    """
    if requested == "NUMPY":
        return "numpy", None
    try:
        import numba  # noqa: F401
    except Exception as error:  # a broken wheel raises more than ImportError (OSError, AttributeError)
        return "numpy", (
            f"compiled kernels unavailable ({type(error).__name__}: {error}); rendering with numpy (slower)"
        )
    return "numba", None


@dataclass
class FrameResult:
    """One rendered frame (row 0 at the top).

    Attributes:
        rgba: (H, W, 4) float32 premultiplied linear RGBA.
        depth: (H, W) float32 window depth of the nearest surface (1 = empty).
        passes: ``ambient``, ``diffuse``, ``specular`` (H, W, 3) and ``shadow`` (H, W, 1) float32,
            premultiplied by coverage; ``shadow`` is the mean light visibility (coverage when
            nothing casts a shadow); with a Cryptomatte request also its RGBA rank/coverage passes
            ``CryptoObject00`` … (H, W, 4).
        choices: what was done for each concern and why (for the Render panel and reports).
        seconds: wall time per stage; ``compile``: the seconds numba spent compiling kernels while
            the frame waited (absent when every kernel was already loaded).
        triangles: input triangle count.
        deep: with ``options.deep_output`` the frame's fragments as a
            :class:`compositing.deep.DeepImage` (``blinn_phong.frame.render(..., deep=True)``), else None.
    """

    rgba: np.ndarray
    depth: np.ndarray
    passes: dict[str, np.ndarray]
    choices: dict[str, object]
    seconds: dict[str, float] = field(default_factory=dict)
    triangles: int = 0
    deep: Any = None


def _shadow_argument(
    scene: Scene, options: RenderOptions, light_radii: tuple[float, ...], casts_shadows: tuple[bool, ...]
) -> object:
    """``render(shadows=...)``: None (the planner's choice per light), one method for every light, or
    one entry per light: ``"none"`` for a light whose Cast Shadow is off, ``ShadowOptions`` with the
    light's own radius for soft shadows."""
    method = SHADOW_SETTINGS[options.shadows]
    n = len(scene.lights)
    radii = tuple(light_radii) or (0.0,) * n
    if len(radii) != n:
        raise ValueError(f"light_radii: expected {n} radii (one per scene light), got {len(radii)}")
    casts = tuple(casts_shadows) or (True,) * n
    if len(casts) != n:
        raise ValueError(f"casts_shadows: expected {n} flags (one per scene light), got {len(casts)}")
    if method != "soft" and all(casts):
        return method
    per_light: list[object] = []
    for radius, cast in zip(radii, casts, strict=True):
        if not cast:
            per_light.append("none")
        elif method == "soft":
            per_light.append(
                ShadowOptions(
                    method="soft", samples=options.shadow_samples, radius=radius, offset=options.shadow_bias
                )
            )
        else:
            per_light.append(ShadowOptions(method=method))
    return per_light


def render_frame(
    scene: Scene,
    width: int,
    height: int,
    options: RenderOptions | None = None,
    *,
    light_radii: tuple[float, ...] = (),
    casts_shadows: tuple[bool, ...] = (),
    progress: Callable[[str, float], None] | None = None,
    cryptomatte: Cryptomatte | None = None,
    light_groups: LightGroups | None = None,
) -> FrameResult:
    """Render ``scene`` (``width × height``) with the settings in ``options``.

    Args:
        scene: the converted scene.
        width: image width in pixels.
        height: image height in pixels.
        options: the render settings (defaults: ``RenderOptions()``); shading, samples per pixel
            (``samples_per_axis²``), transparency, shadows, fog, tolerance and kernels.
        light_radii: radius per entry of ``scene.lights`` (soft shadows), scene units.
        casts_shadows: per entry of ``scene.lights``, False when the light casts no shadow
            (Blender's Light › Cast Shadow off): that light gets the method ``"none"``.
        progress: optional ``callback(stage, fraction_done)``.
        cryptomatte: a :class:`blinn_phong.Cryptomatte` request, or None: its passes
            (``CryptoObject00`` …) are added to ``passes``.
        light_groups: a :class:`blinn_phong.LightGroups`, or None: its ``Combined_<group>``
            passes are added to ``passes``.

    Returns:
        :class:`FrameResult`; ``choices["reasons"]`` holds one line per decision of the plan that
        was followed, ``choices["engine"]`` the kernels that ran and ``choices["embree"]`` whether
        Embree was available; ``deep`` the deep image when ``options.deep_output`` is on.

    Raises:
        ValueError: ``options.deep_output`` with a Transparency setting that keeps no depth order
            (:func:`addon.options.deep_output_problem`), before anything is rendered.
    """
    options = options or RenderOptions()
    if options.deep_output and (problem := deep_output_problem(options.transparency)):
        raise ValueError(f"deep_output (Deep EXR): {problem}")
    shadows = _shadow_argument(scene, options, tuple(light_radii), tuple(casts_shadows))
    fog = None
    if options.fog != "NONE":
        fog = Fog(
            mode=options.fog.lower(),
            color=options.fog_color,
            density=options.fog_density,
            start=options.fog_start,
            end=options.fog_end,
        )
    kernels, warning = kernel_engine(options.engine)
    with compile_clock() as compiling:  # kernels compiled inside the frame (e.g. ray-traced shadows)
        result = render(
            scene,
            width,
            height,
            shading=options.core_shading,
            samples=options.samples,
            engine=kernels,
            progress=progress,
            transparency=TRANSPARENCY_SETTINGS[options.transparency],
            peel_layers=options.peel_layers if options.transparency == "DEPTH_PEELING" else None,
            shadows=shadows,
            fog=fog,
            tolerance=options.tolerance,
            cryptomatte=cryptomatte,
            light_groups=light_groups,
            deep=options.deep_output,
        )
    passes = dict(result.passes)
    passes.setdefault("shadow", result.rgba[..., 3:4].copy())
    followed = result.plan
    lit = [i for i, light in enumerate(scene.lights) if not isinstance(light, AmbientLight)]
    choices: dict[str, object] = {
        "shading": options.core_shading,
        "samples": options.samples,
        "transparency": followed.transparency.method,
        "shadows": [followed.shadows[i].method for i in lit],
        "fog": options.fog,
        "reasons": followed.reasons(),
        "engine": kernels,
        "embree": embree_available(),
        "warnings": [warning] if warning else [],
    }
    seconds = dict(result.stats.seconds)
    if compiling.seconds:
        seconds["compile"] = compiling.seconds
    return FrameResult(
        result.rgba, result.depth, passes, choices, seconds, result.stats.triangles, deep=result.deep
    )
