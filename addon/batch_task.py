"""One task of a batch job: render a frame in this process (``bpy``), write its outputs, composite, verify.

:func:`run_task` is what every executor runs: in this process, in a worker process of the local
pool, or on a Dask worker (which imports it by this module's name, so the worker needs the
repository on its ``sys.path``). Each attempt leaves a marker in the job's folder
(:func:`_record_attempt`, :func:`_finish_attempt`); a finished attempt's result is returned
instead of rendering the frame again (:func:`_finished_result`).
"""

from __future__ import annotations

import json
import os
import re
import socket
import sys
import threading
import time
import traceback
from dataclasses import asdict
from pathlib import Path
from typing import Any

from .batch_files import atomic_target, read_back, readable, write_permit
from .batch_job import MAX_FRAME, MIN_FRAME, JobClosed, Task, _trim, parse_colour


def _engine_module() -> Any:
    """The module of the registered Blinn-Phong engine (repository copy or installed extension)."""
    import bpy

    for cls in bpy.types.RenderEngine.__subclasses__():
        if getattr(cls, "bl_idname", None) == "BLINN_PHONG" and getattr(cls, "is_registered", False):
            return sys.modules[cls.__module__]
    return None


_BLENDER_SCRIPTS = re.compile(r"[/\\](bpy|blender)[/\\]\d+\.\d+[/\\]scripts([/\\]|$)")


def _unshadow_bpy() -> None:
    """Drop Blender's script directories from ``sys.path`` in a process that has not imported bpy.

    Spawned workers inherit the parent's ``sys.path``; after ``import bpy`` it holds Blender's
    ``scripts/modules``, whose ``bpy`` package (for Blender's own executable) would shadow the
    ``bpy`` module. The worker's own ``import bpy`` adds them back.
    """
    if "bpy" not in sys.modules:
        sys.path[:] = [p for p in sys.path if not _BLENDER_SCRIPTS.search(p)]


def _marker(task: Task) -> Path:
    return Path(task.attempt_dir) / f"{task.key}.{socket.gethostname()}.{os.getpid()}"  # type: ignore[arg-type]


def _record_attempt(task: Task) -> bool:
    """Leave a marker ``<attempt_dir>/<key>.<host>.<pid>`` (shared storage): who started the task.

    Returns False when the job has ended (its folder is gone): the task must not run. The folder is
    made by the job, never here.
    """
    if not task.attempt_dir:
        return True
    if not Path(task.attempt_dir).is_dir():
        return False
    try:
        _marker(task).write_text(
            json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "start": time.time()})
        )
    except FileNotFoundError:
        return False
    except OSError:
        pass  # the record is informative; never fail a render for it
    return True


def _finish_attempt(task: Task, result: dict[str, Any]) -> None:
    """Complete this attempt's marker with its end, outcome and, when it succeeded, its result (so
    a finished attempt is never 'lost', and never rendered again: :func:`_finished_result`)."""
    if not task.attempt_dir:
        return
    marker = _marker(task)
    try:
        record = json.loads(marker.read_text())
        record.update(end=time.time(), outcome="ok" if result["ok"] else "failed")
        if result["ok"]:
            record["result"] = result
        marker.write_text(json.dumps(record, default=str))
    except (OSError, ValueError, TypeError):
        pass  # the job has ended (folder renamed) or the marker is unreadable: informative only


def _finished_result(task: Task) -> dict[str, Any] | None:
    """The result of an earlier attempt of ``task`` that succeeded, if every file it wrote is still
    there; else None.

    Dask keeps a task's result on the worker that computed it until the job has fetched it. When
    that worker is lost first, the scheduler computes the task again on another worker: the frame
    is already written, so the earlier attempt's result (kept in its marker by
    :func:`_finish_attempt`) is returned instead of rendering the frame a second time.
    """
    if not task.attempt_dir:
        return None
    for marker in sorted(Path(task.attempt_dir).glob(f"{task.key}.*")):
        try:
            record = json.loads(marker.read_text())
        except (OSError, ValueError):
            continue
        result = record.get("result")
        if record.get("outcome") != "ok" or not isinstance(result, dict):
            continue
        if all(Path(path).is_file() for path in result.get("written", [])):
            return result
    return None


def _watchdog(task: Task) -> threading.Timer | None:
    """In a Dask worker: end the worker process when the task outlives ``task.timeout``.

    A render cannot be interrupted from Python; the worker's nanny starts a fresh worker and the
    scheduler reschedules the task (its retries are bounded by ``distributed.scheduler.allowed-failures``).
    """
    if not task.timeout:
        return None
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return None

    def expire() -> None:
        print(
            f"addon.batch: {task.stem} exceeded --timeout {task.timeout:g} s; ending this worker",
            file=sys.stderr,
            flush=True,
        )
        os._exit(75)

    timer = threading.Timer(task.timeout, expire)
    timer.daemon = True
    timer.start()
    return timer


def run_task(task: Task | dict) -> dict[str, Any]:
    """Run one task in this process (which must have ``bpy``); never raises, returns a result dict.

    The result holds ``ok``, ``error`` (trimmed text), ``written`` (every file written, absolute
    paths), ``outputs`` by role, ``seconds`` per stage, ``warnings``, ``pid`` and ``host``.

    Every file is written through :func:`atomic_target` under the job's :func:`write_permit` and
    read back whole (:func:`read_back`) before it replaces anything; a write that fails — also one
    that Blender only logs, such as a full disk — fails the task and keeps the previous file.
    """
    if isinstance(task, dict):
        task = Task(**task)
    _unshadow_bpy()
    started = time.perf_counter()
    result: dict[str, Any] = {
        "task": asdict(task),
        "ok": False,
        "error": None,
        "outputs": {},
        "written": [],
        "warnings": [],
        "seconds": {},
        "pid": os.getpid(),
        "host": socket.gethostname(),
    }
    earlier = _finished_result(task)
    if earlier is not None:  # its worker was lost before the job fetched the result
        return earlier
    if not _record_attempt(task):
        result["error"] = f"JobClosed: the job has ended before {task.stem} started; nothing was rendered"
        result["seconds"]["total"] = time.perf_counter() - started
        return result
    timer = _watchdog(task)
    registered_here: list[Any] = []
    placeholders: list[Path] = []
    engine_module: Any = None
    write_deep_files = True
    try:
        import bpy

        from . import compat, engine, mapping, properties

        if _engine_module() is None:
            for module in (properties, engine):
                module.register()
                registered_here.append(module)
        bpy.ops.wm.open_mainfile(filepath=str(Path(task.blend).resolve()), load_ui=False)
        scene = bpy.context.scene
        scene.render.engine = engine.ENGINE_ID
        scene.blinn_phong.abort_on_error = False
        # The deep image is written here, under the job's rules, never by the engine itself.
        scene.blinn_phong.deep_output = bool(task.deep_output)
        engine_module = _engine_module()
        write_deep_files, engine_module.WRITE_DEEP_FILES = engine_module.WRITE_DEEP_FILES, False
        scene.frame_set(task.frame)
        if scene.frame_current != task.frame:  # Blender clamps to its frame range
            raise ValueError(
                f"frame {task.frame}: Blender set the scene to frame {scene.frame_current} instead "
                f"(its frame range is {MIN_FRAME}..{MAX_FRAME}); nothing was written"
            )
        settings = scene.render.image_settings
        if task.file_format:
            compat.set_image_format(settings, task.file_format, task.color_depth)
        elif task.color_depth:
            settings.color_depth = task.color_depth
        output = Path(task.output)
        for marked in map(Path, task.placeholder_paths()):
            if marked.exists():
                continue
            with write_permit(task):
                marked.parent.mkdir(parents=True, exist_ok=True)
                try:  # an ordinary empty file: 0o666 minus the umask, as the frame itself gets
                    fd = os.open(marked, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
                    os.close(fd)
                    placeholders.append(marked)
                except FileExistsError:
                    pass
        t = time.perf_counter()
        _engine_module().LAST_RENDER.clear()  # no status of an earlier task in this worker
        try:
            bpy.ops.render.render()
        except RuntimeError as error:  # Blender turns the engine's error report into an exception
            status = dict(_engine_module().LAST_RENDER)
            raise RuntimeError(_trim(status.get("error") or error)) from None
        result["seconds"]["render"] = time.perf_counter() - t
        status = dict(_engine_module().LAST_RENDER)
        # stats: seconds per stage, and "compile" when the frame waited for kernels to compile
        result["render"] = {k: status.get(k) for k in ("ok", "error", "choices", "notes", "size", "stats")}
        if not status.get("ok"):
            raise RuntimeError(_trim(status.get("error") or "the engine reported no successful render"))
        render = scene.render
        size = mapping.render_size(render.resolution_x, render.resolution_y, render.resolution_percentage)
        render_result = bpy.data.images["Render Result"]
        t = time.perf_counter()
        try:
            with (
                write_permit(task),
                atomic_target(output, job=task.job, check=lambda tmp: read_back(tmp, size)) as tmp,
            ):
                render_result.save_render(filepath=str(tmp), scene=scene)
        except OSError as error:
            raise OSError(f"writing {output} failed, the previous file is kept: {error}") from None
        result["seconds"]["write"] = time.perf_counter() - t
        if not readable(output):
            result["warnings"].append(
                f"{output.suffix} files cannot be read back here (OpenImageIO has no reader for them): "
                "written without the check that the write succeeded"
            )
        placeholders = [p for p in placeholders if p != output]
        result["outputs"]["render"] = str(output)
        result["written"].append(str(output))
        result["format"] = {"file_format": settings.file_format, "color_depth": settings.color_depth}
        if task.deep_output:
            _write_deep_output(task, engine_module, size, result)
            placeholders = [p for p in placeholders if p != Path(task.deep_output)]
        if task.background:
            rendered = _linear_render(scene, render_result, output, settings)
            _composite_and_verify(task, rendered, scene.render.film_transparent, result)
        result["ok"] = result.get("verify", {}).get("ok", True)
        if not result["ok"]:
            result["error"] = (
                f"verification error {result['verify']['max_abs_error']:.3g} exceeds "
                f"--tolerance {task.tolerance:g}"
            )
    except Exception as error:
        message = _trim(error)
        result["error"] = (
            message if message.startswith("Blinn-Phong") else f"{type(error).__name__}: {message}"
        )
        result["traceback"] = traceback.format_exc()
    finally:
        if timer is not None:
            timer.cancel()
        if engine_module is not None:
            engine_module.WRITE_DEEP_FILES = write_deep_files
            engine_module.LAST_DEEP.clear()  # the deep image's memory
        for placeholder in placeholders:
            try:
                with write_permit(task):
                    if placeholder.stat().st_size == 0:
                        placeholder.unlink()
            except (OSError, JobClosed):
                pass  # the job has ended: its own clean-up removes placeholders
        for module in reversed(registered_here):
            try:
                module.unregister()
            except Exception as error:
                result.setdefault("cleanup_errors", []).append(repr(error))
        result["seconds"]["total"] = time.perf_counter() - started
        _finish_attempt(task, result)
    return result


def _write_deep_output(task: Task, engine_module: Any, size: tuple[int, int], result: dict[str, Any]) -> None:
    """Write the engine's deep image of the frame (``LAST_DEEP``) to ``task.deep_output``: through
    :func:`atomic_target` under the job's permit, read back whole (every sample) before it
    replaces anything."""
    from compositing.deep_io import write_deep

    image = engine_module.LAST_DEEP.get("image")
    if image is None:
        raise RuntimeError(f"{task.stem}: the engine returned no deep image; {task.deep_output} not written")
    t = time.perf_counter()
    try:
        with (
            write_permit(task),
            atomic_target(task.deep_output, job=task.job, check=lambda tmp: read_back(tmp, size)) as tmp,
        ):
            write_deep(tmp, image, atomic=False)  # tmp is already this job's temporary file
    except OSError as error:
        raise OSError(f"writing {task.deep_output} failed, the previous file is kept: {error}") from None
    result["seconds"]["write_deep"] = time.perf_counter() - t
    result["outputs"]["deep"] = task.deep_output
    result["written"].append(task.deep_output)
    result["deep"] = {"samples": int(image.n_samples), "max_per_pixel": int(image.counts.max(initial=0))}


def _linear_render(scene: Any, render_result: Any, output: Path, settings: Any) -> Any:
    """The render as linear premultiplied float32 RGBA, whatever format the output file has."""
    import tempfile

    from compositing.io import read_image

    from . import compat
    from .verify import read_exr_layers

    if settings.file_format == "OPEN_EXR" and settings.color_depth == "32" and settings.color_mode == "RGBA":
        return read_image(output)
    if settings.file_format == "OPEN_EXR_MULTILAYER" and settings.color_depth == "32":
        layers = read_exr_layers(output)
        combined = [name for name in layers if name.endswith(".Combined")]
        if combined:
            return layers[combined[0]]
    # Another format (PNG, half float, ...): a linear 32-bit copy for compositing only.
    saved = (settings.file_format, settings.color_depth, settings.color_mode)
    with tempfile.TemporaryDirectory(prefix="batch-linear-") as tmp:
        path = Path(tmp) / "combined.exr"
        try:
            compat.set_image_format(settings, "OPEN_EXR", "32")
            settings.color_mode = "RGBA"
            render_result.save_render(filepath=str(path), scene=scene)
        finally:
            compat.set_image_format(settings, saved[0], saved[1])
            settings.color_mode = saved[2]
        return read_image(path)


def _composite_and_verify(task: Task, rendered: Any, film_transparent: bool, result: dict[str, Any]) -> None:
    import numpy as np

    from compositing import composite
    from compositing.io import write_image

    background = _background_image(task.background, *rendered.shape[:2])
    t = time.perf_counter()
    composited = composite(rendered, background, task.operator)
    result["seconds"]["composite"] = time.perf_counter() - t
    if film_transparent and np.array_equal(composited, rendered):
        # (With Film → Transparent off the job's plan has already warned once per file.)
        result["warnings"].append(
            f"{task.stem}: --background with --operator {task.operator} does not change the image"
        )
    exr_path, png_path = task.composite_paths()
    size = (rendered.shape[1], rendered.shape[0])
    for path, clip in ((exr_path, False), (png_path, True)):
        try:
            with (
                write_permit(task),
                atomic_target(path, job=task.job, check=lambda tmp: read_back(tmp, size)) as tmp,
            ):
                write_image(tmp, composited, clip=clip)
        except OSError as error:
            raise OSError(f"writing {path} failed, the previous file is kept: {error}") from None
        result["written"].append(path)
    result["outputs"]["composite"] = exr_path
    result["outputs"]["preview"] = png_path
    if task.verify:
        from .verify import verify

        t = time.perf_counter()
        via = "alpha_over" if task.operator == "src_over" else "node_group"
        check = verify(rendered, background, task.operator, via=via)
        result["seconds"]["verify"] = time.perf_counter() - t
        result["verify"] = {
            "via": via,
            "max_abs_error": check.max_abs_error,
            "mean_abs_error": check.mean_abs_error,
            "ok": check.max_abs_error <= task.tolerance,
        }


def _background_image(spec: str, height: int, width: int) -> Any:
    """The background: an image file of the render's size, or a colour ``r,g,b[,a]`` (linear, straight)."""
    import numpy as np

    values = parse_colour(spec)
    if values is None:
        from compositing.io import read_image

        image = read_image(spec)
        if image.shape[:2] != (height, width):
            raise ValueError(
                f"--background: {spec} is {image.shape[1]}×{image.shape[0]} "
                f"but the render is {width}×{height}"
            )
        return image
    rgba = np.array([*values[:3], values[3] if len(values) == 4 else 1.0], dtype=np.float32)
    rgba[:3] *= rgba[3]  # premultiply
    return np.broadcast_to(rgba, (height, width, 4)).copy()
