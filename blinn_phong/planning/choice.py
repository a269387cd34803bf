"""What the planner returns: a :class:`Choice` per concern (method, parameters, the reason, and
for approximations the predicted error and relative cost) gathered in a :class:`Plan`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["DEFAULT_FRAME", "Choice", "Plan"]


@dataclass(frozen=True)
class Choice:
    """One decision: ``method``, its ``params``, the ``reason`` and, for approximations, predictions.

    ``params`` are keyword arguments of the function that carries the method out:
    ``layers`` for :func:`blinn_phong.effects.oit.resolve_transparency`, ``plane`` or ``resolution``
    for :func:`blinn_phong.shadows.methods.light_visibility`. ``predicted_steps`` is the error the
    calibrated model predicts (8-bit steps, in the concern's metric, see :func:`plan`; 0 for
    the exact method of a concern) and ``relative_cost`` the predicted time relative to that
    exact method (A-buffer, ray tracing, Phong); both None where no model applies.
    """

    method: str
    reason: str
    params: dict[str, object] = field(default_factory=dict)
    predicted_steps: float | None = None
    relative_cost: float | None = None

    def __str__(self) -> str:
        extra = ", ".join(f"{k}={v}" for k, v in self.params.items())
        return f"{self.method}{f' ({extra})' if extra else ''}: {self.reason}"


@dataclass(frozen=True)
class Plan:
    """The planner's decisions for one scene.

    Attributes:
        transparency: how transparent fragments are resolved.
        shadows: one choice per entry of ``scene.lights`` (same order).
        shading: one choice per entry of ``scene.meshes`` (same order).
        tolerance: the tolerance the plan was made for, in 8-bit steps (0: exact only).
        fog: with fog, what it does to the error bounds and what it costs (None without fog).
    """

    transparency: Choice
    shadows: tuple[Choice, ...]
    shading: tuple[Choice, ...]
    tolerance: float
    fog: Choice | None = None

    def reasons(self) -> list[str]:
        """Every decision as one human-readable line."""
        lines = [f"transparency: {self.transparency}"]
        lines += [f"shadows, light {i}: {c}" for i, c in enumerate(self.shadows)]
        lines += [f"shading, mesh {i}: {c}" for i, c in enumerate(self.shading)]
        if self.fog is not None:
            lines.append(f"fog: {self.fog}")
        return lines

    def __str__(self) -> str:
        return "\n".join(self.reasons())


# --------------------------------------------------------------------------- decisions


DEFAULT_FRAME = (640, 480, 1)


@dataclass(frozen=True)
class _Frame:
    width: int
    height: int
    samples: int

    @property
    def samples_total(self) -> int:
        """Samples of the frame, ``width·height·samples`` (``samples`` per pixel, a k×k grid, as
        ``render`` takes it): what rasterization, shading and the resolve scale with."""
        return self.width * self.height * self.samples

    @property
    def receivers(self) -> int:
        """Shading samples of the frame, ``width·height·samples`` (the points that need a visibility)."""
        return self.width * self.height * self.samples


def _frame(width: int | None, height: int | None, samples: int) -> _Frame:
    w = DEFAULT_FRAME[0] if width is None else width
    h = DEFAULT_FRAME[1] if height is None else height
    for name, value in (("width", w), ("height", h), ("samples", samples)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return _Frame(int(w), int(h), int(samples))
