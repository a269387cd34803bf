"""The batch job's plan: every file opened once (``bpy``), each task's outputs resolved and checked.

:func:`plan_job` runs before the first render: output paths from the file's settings or
``--output-pattern``, duplicate outputs, output folders, the background's size, ``--deep``'s
requirements, and with ``--skip-existing`` which frames are already done.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .batch_cli import _check_writable_dir
from .batch_files import _incomplete
from .batch_job import FORMATS, Task, UsageError, _trim, parse_colour
from .batch_task import _engine_module


@dataclass
class Plan:
    """What the job will do, worked out before the first render."""

    tasks: list[Task]
    skipped: list[dict[str, Any]]
    warnings: list[str]
    job: str = ""
    attempt_dir: str | None = None
    outside_out: list[str] = field(default_factory=list)


@contextlib.contextmanager
def _engine_registered() -> Iterator[None]:
    """The engine and its settings registered for the block (unless they already are).

    Files saved with the Blinn-Phong engine name it in their scene; opening one without it makes
    Blender log "Engine 'BLINN_PHONG' not available" and drop its settings. A RenderEngine left
    registered at exit crashes bpy 4.2, so what is registered here is unregistered after.
    """
    from . import engine, properties

    registered: list[Any] = []
    try:
        if _engine_module() is None:
            for module in (properties, engine):
                module.register()
                registered.append(module)
        yield
    finally:
        for module in reversed(registered):
            with contextlib.suppress(Exception):
                module.unregister()


def plan_job(args: argparse.Namespace, blends: Sequence[str], frames: list[int] | None) -> Plan:
    """Open every file once (``bpy``) and resolve each task's outputs; check what needs the file.

    Checks: the background's size against each file's render size; that no two tasks write the
    same file; that every output folder can be created and written; that each file's format
    accepts the colour depth. With ``--skip-existing`` a frame counts as done only when each of its
    outputs is a whole image of the render's size (:func:`read_back`). Warns when a requested
    composite cannot change the image (Film → Transparent off with an operator an opaque source
    decides) and when ``--output-pattern`` leads outside ``--out`` (such paths are listed in
    ``Plan.outside_out``).

    Raises:
        UsageError: naming the flag or file.
    """
    with _engine_registered():
        return _plan_job(args, blends, frames)


def _plan_job(args: argparse.Namespace, blends: Sequence[str], frames: list[int] | None) -> Plan:
    import bpy
    import numpy as np

    from compositing import composite

    from . import compat, mapping, options

    out_dir = args.out.resolve()
    problems: list[str] = []
    warnings: list[str] = []
    tasks: list[Task] = []
    skipped: list[dict[str, Any]] = []
    owners: dict[str, str] = {}
    background_size = None
    if args.background and parse_colour(args.background) is None:
        import OpenImageIO as oiio  # noqa: N813

        inp = oiio.ImageInput.open(args.background)
        background_size = (inp.spec().width, inp.spec().height)
        inp.close()
        from compositing.io import read_image
        from compositing.validate import check_alpha_range

        try:  # decoded once here, so that bad pixels are found before the first render
            check_alpha_range(read_image(args.background), "pixels")
        except (OSError, ValueError) as error:
            problems.append(f"--background: {args.background}: {error}")
    # The job's folder (shared storage on a cluster): each attempt leaves a marker there, for the
    # report, and every write needs it (write_permit); the job removes it when it ends.
    job = uuid.uuid4().hex[:12]
    attempt_dir = str(out_dir / f".batch-{job}")
    outside_out: list[str] = []
    checked_dirs: dict[Path, str | None] = {}
    planned: list[tuple[Task, tuple[int, int] | None]] = []  # each task, and its size if it may be skipped
    # An opaque source decides the result of these operators: the composite equals the render.
    opaque = np.array([[[0.25, 0.5, 0.75, 1.0]]], np.float32)
    probe_bg = np.array([[[0.1, 0.7, 0.3, 0.6]]], np.float32)
    inert_when_opaque = bool(np.array_equal(composite(opaque, probe_bg, args.operator), opaque))

    for blend in blends:
        path = Path(blend).resolve()
        try:
            bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
        except RuntimeError as error:
            problems.append(f"{blend}: Blender cannot open it ({_trim(error)})")
            continue
        scene = bpy.context.scene
        render = scene.render
        settings = render.image_settings
        if args.format:
            compat.set_image_format(settings, args.format, None)
        file_format = settings.file_format
        if args.color_depth:
            allowed = FORMATS.get(file_format)
            if allowed is not None and args.color_depth not in allowed:
                problems.append(
                    f"--color-depth: {blend} writes {file_format}, which accepts {'/'.join(allowed)}, "
                    f"not {args.color_depth}"
                )
                continue
            settings.color_depth = args.color_depth
        size = mapping.render_size(render.resolution_x, render.resolution_y, render.resolution_percentage)
        if background_size is not None and background_size != size:
            problems.append(
                f"--background: {args.background} is {background_size[0]}×{background_size[1]} but "
                f"{blend} renders {size[0]}×{size[1]}"
            )
        if args.background and not render.film_transparent and inert_when_opaque:
            warnings.append(
                f"{blend}: Film → Transparent is off, so the render is opaque and --operator "
                f"{args.operator} over --background gives back the render unchanged"
            )
        pattern = args.output_pattern if args.output_pattern is not None else render.filepath
        pattern = _expand_tokens(pattern, path, scene)
        if not pattern.startswith("//") and not os.path.isabs(pattern):
            pattern = str(out_dir / pattern) + ("/" if pattern.endswith(("/", os.sep)) or not pattern else "")
        render.filepath = pattern
        skip = args.skip_existing or not render.use_overwrite
        placeholder = args.placeholders or render.use_placeholder
        deep = bool(getattr(args, "deep", False)) or scene.blinn_phong.deep_output
        if deep and (problem := options.deep_output_problem(scene.blinn_phong.transparency)):
            flag = "--deep" if getattr(args, "deep", False) else "Deep EXR (scene.blinn_phong.deep_output)"
            problems.append(f"{flag}: {blend}: scene {scene.name!r}: {problem}")
            continue
        extension = render.file_extension if render.use_file_extension else ""
        source = "--output-pattern" if args.output_pattern is not None else f"{blend}: render.filepath"
        for frame in frames if frames is not None else [scene.frame_current]:
            try:
                output = str(Path(bpy.path.abspath(render.frame_path(frame=frame))).resolve())
            except RuntimeError as error:  # Blender 5.0 path templates: unknown or broken {…}
                problems.append(f"{source}: {_trim(error).removeprefix('Error: ')}")
                break
            task = Task(
                blend=str(path),
                frame=frame,
                out_dir=str(out_dir),
                output=output,
                deep_output=options.deep_output_path(output, extension) if deep else "",
                file_format=args.format,
                color_depth=args.color_depth,
                output_pattern=args.output_pattern,
                background=args.background,
                operator=args.operator,
                verify=args.verify,
                tolerance=args.tolerance,
                placeholder=placeholder,
                timeout=args.timeout,
                attempt_dir=attempt_dir,
                job=job,
            )
            name = f"{blend} frame {frame}"
            for target in task.outputs():
                if target in owners:
                    problems.append(f"{name} and {owners[target]} both write {target}")
                owners[target] = name
                if Path(target).is_dir():
                    problems.append(f"{name}: its output {target} is a directory")
                folder = Path(target).parent
                if folder not in checked_dirs:
                    try:
                        _check_writable_dir(folder, source)
                        checked_dirs[folder] = None
                    except UsageError as error:
                        checked_dirs[folder] = str(error)
                        problems.append(str(error))
                if not Path(target).is_relative_to(out_dir):
                    outside_out.append(target)
            planned.append((task, size if skip else None))
    if any("both write" in p for p in problems):
        problems.append(
            "give each file its own output path (render.filepath in the file, or --output-pattern "
            "with {blend_name} / {blend_dir_name}, e.g. '{blend_dir_name}/{blend_name}_####')"
        )
    if problems:
        raise UsageError("\n  ".join(problems))
    # --skip-existing: decode the outputs that exist (in threads: OpenImageIO decodes without the GIL).
    from concurrent.futures import ThreadPoolExecutor

    checks = [(task.outputs(), size) for task, size in planned if size is not None]
    with ThreadPoolExecutor(max_workers=max(1, min(8, os.cpu_count() or 1))) as pool:
        verdicts = iter(list(pool.map(lambda check: _incomplete(*check), checks)))
    for task, size in planned:
        if size is not None:
            missing = next(verdicts)
            if not missing:
                skipped.append({"blend": task.blend, "frame": task.frame, "outputs": task.outputs()})
                continue
            for target, why in missing:
                if why:  # a file is there but is not a whole image: rendered again
                    warnings.append(
                        f"{target} is not a whole image ({why}); rendering frame {task.frame} again"
                    )
        tasks.append(task)
    if args.output_pattern is not None and outside_out:
        warnings.append(
            f"--output-pattern {args.output_pattern!r} writes {len(outside_out)} file(s) outside --out "
            f"{out_dir} (e.g. {outside_out[0]}); the report lists them under 'outside_out'"
        )
    bpy.ops.wm.read_homefile(use_empty=True)
    return Plan(tasks, skipped, warnings, job, attempt_dir, outside_out)


def _expand_tokens(pattern: str, blend: Path, scene: Any) -> str:
    """Our tokens in ``--output-pattern`` (Blender 5.0 resolves its own path templates as well)."""
    values = {
        "{blend_name}": blend.stem,
        "{blend_dir_name}": blend.parent.name,
        "{scene}": scene.name,
        "{camera}": scene.camera.name if scene.camera else "no_camera",
    }
    for token, value in values.items():
        pattern = pattern.replace(token, value)
    return pattern
