"""What a batch job tells its user: progress while it runs, and its JSON record when it ends."""

from __future__ import annotations

import argparse
import json
import sys
import time
import uuid
from pathlib import Path
from typing import Any, TextIO

from .batch_files import write_text_atomic
from .batch_job import EXIT_FAILED, SchedulerUnreachable, _trim


class Progress:
    """A tqdm bar over frames on a terminal, one plain line per finished task otherwise.

    Everything goes to ``stream`` (stderr); ``quiet`` silences both. Per-frame time is shown as
    the bar's postfix and in the plain lines.
    """

    def __init__(self, total: int, stream: TextIO = sys.stderr, *, quiet: bool = False) -> None:
        self.total, self.done, self.failed, self.stream, self.quiet = total, 0, 0, stream, quiet
        self.bar = None
        if not quiet and stream.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, file=stream, unit="frame", dynamic_ncols=True)

    def note(self, text: str) -> None:
        """A line of text that does not break the bar (retries, warnings)."""
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            self.stream.write(text + "\n")
            self.stream.flush()

    def update(self, result: dict[str, Any]) -> None:
        """Record one finished task."""
        self.done += 1
        self.failed += not result["ok"]
        task = result["task"]
        name = f"{Path(task['blend']).name} frame {task['frame']}"
        error = _trim(result["error"]).splitlines()[0] if result["error"] else ""
        status = "ok" if result["ok"] else f"FAILED ({error})"
        seconds = result["seconds"].get("total", 0.0)
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.set_postfix_str(f"{name} {seconds:.2f} s/frame, {self.failed} failed", refresh=False)
            if not result["ok"]:
                self.bar.write(f"{name}: {status}", file=self.stream)
            self.bar.update(1)
            if self.done == self.total:
                self.bar.close()
        else:
            self.stream.write(f"[{self.done}/{self.total}] {name}: {status} ({seconds:.2f} s)\n")
            self.stream.flush()

    def close(self) -> None:
        """Close the bar (if any)."""
        if self.bar is not None:
            self.bar.close()


def _write_reports(args: argparse.Namespace, report: dict[str, Any]) -> Path:
    """Write the job's record ``OUT/reports/<time>-<job>.json``, then ``--report`` (``OUT/report.json``).

    Jobs sharing an ``--out`` each keep their own record; ``report.json`` is the last job to end
    (each file is written atomically, so it is always one whole report). Returns ``report.json``'s path.
    """
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime())
    own = (args.out / "reports" / f"{stamp}-{report['job'] or uuid.uuid4().hex[:12]}.json").resolve()
    report["job_report"] = str(own)
    text = json.dumps(report, indent=1, default=str)
    write_text_atomic(own, text)
    report_path = (args.report or args.out / "report.json").resolve()
    write_text_atomic(report_path, text)
    return report_path


def _unreachable(args: argparse.Namespace, error: SchedulerUnreachable, executor: str, started: float) -> int:
    """``--scheduler`` cannot be reached: say so in one line and in the report; nothing was rendered."""
    print(f"error: {error}", file=sys.stderr)
    report = {
        "job": "",
        "tasks": [],
        "failed": 0,
        "total": 0,
        "written": [],
        "outside_out": [],
        "skipped": [],
        "retried": [],
        "warnings": [],
        "seconds": time.perf_counter() - started,
        "executor": executor,
        "exit_code": EXIT_FAILED,
        "interrupted": None,
        "error": str(error),
    }
    report_path = _write_reports(args, report)
    print(f"nothing rendered; report: {report_path}")
    return EXIT_FAILED
