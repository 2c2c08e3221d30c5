"""Running a study: every run not yet recorded, its record written as it finishes, then the
table and the report.

Backends (:func:`make_backend`): ``workers=0`` runs in this process, one run after the other
(for debuggers and profilers); by default a local process pool
(:class:`~flexctrl.study.backends.LocalPoolBackend`); a Dask cluster on request
(``scheduler="tcp://host:8786"`` or ``client=...``,
:class:`~flexctrl.study.dask_backend.DaskBackend`).  Results come back as plain data and the
parent writes them as they arrive (:mod:`flexctrl.study.store` says why the parent is the only
writer).
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError, keyword_checked
from flexctrl.study.backends import InProcessBackend, LocalPoolBackend, default_workers
from flexctrl.study.dask_backend import DaskBackend
from flexctrl.study.plan import StudySpec
from flexctrl.study.run_execution import peak_memory_mb
from flexctrl.study.store import ResultStore, Table, now_iso

STUDY_FORMAT = 1
VERSIONED = (
    "flexctrl",
    "numpy",
    "scipy",
    "casadi",
    "control",
    "osqp",
    "matplotlib",
    "dask",
    "distributed",
)


def versions() -> dict[str, str]:
    """Installed versions of flexctrl and the libraries that shape its numbers."""
    found = {"python": platform.python_version()}
    for name in VERSIONED:
        try:
            found[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def machine() -> dict[str, Any]:
    """Platform, CPUs and memory of this machine."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "hostname": platform.node(),
        "cpu_count": os.cpu_count(),
        "usable_cpus": default_workers(),
    }
    try:
        info["memory_gb"] = round(
            os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 2**30, 2
        )
    except (AttributeError, ValueError, OSError):  # pragma: no cover
        pass
    return info


@dataclass
class StudyResult:
    """What :func:`run_study` did.

    Attributes
    ----------
    directory : Path
    counts : dict
        ``ok``, ``failed``, ``pending`` over the whole grid; ``ran`` and
        ``skipped`` in this session.
    elapsed_s : float
        Wall time of this session (s).
    interrupted : bool
        True if stopped by Ctrl-C (finished runs are kept).
    report : Path or None
    backend : str
    """

    directory: Path
    counts: dict[str, int]
    elapsed_s: float
    interrupted: bool = False
    report: Path | None = None
    backend: str = ""
    warnings: list[str] = field(default_factory=list)

    @property
    def table_path(self) -> Path:
        """``results.csv``."""
        return self.directory / "results.csv"

    def table(self) -> Table:
        """``results.csv`` read back."""
        return Table.read(self.table_path)

    def to_pandas(self):
        """``results.csv`` as a pandas DataFrame."""
        return self.table().to_pandas()


def make_backend(
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    blas_threads: int | str = "auto",
):
    """The backend for the given options (see the module docstring); call its ``start()`` and
    ``close()``.

    ``blas_threads``: BLAS threads per local worker
    (:func:`~flexctrl.study.blas_threads.blas_thread_budget`).
    """
    if scheduler is not None or client is not None:
        if workers is not None:
            raise SpecError(
                "--workers sizes the local pool; with --scheduler the cluster's workers run the "
                "study",
                key="--workers",
            )
        return DaskBackend(scheduler, client)
    if workers is not None and workers < 0:
        raise SpecError(
            f"value {workers} is not allowed; allowed: 0 (in this process) or more workers",
            key="--workers",
        )
    if workers == 0:
        return InProcessBackend()
    return LocalPoolBackend(workers if workers is not None else default_workers(), blas_threads)


@keyword_checked
def run_study(
    spec: StudySpec,
    out: str | os.PathLike,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    resume: bool = False,
    progress: str = "auto",
    stream=None,
    report: bool = True,
    blas_threads: int | str = "auto",
) -> StudyResult:
    """Run every run of ``spec`` not yet recorded in ``out``; write the table and the report.

    Parameters
    ----------
    spec
        From :func:`flexctrl.study.study_file.load_study` (validated before anything runs).
    out
        The result folder (see :mod:`flexctrl.study.store`).
    workers
        Local pool size (default: the usable CPUs; 0: in this process).
    scheduler, client
        A Dask scheduler address or client instead of the local pool.
    resume
        Continue an interrupted study: ``out`` must hold it already; runs with
        a record (ok or failed) are kept.  Without it, runs recorded ok are kept
        and failed ones are run again.
    progress
        ``auto``, ``bar``, ``lines`` or ``none`` (see :class:`~flexctrl.study.progress.Progress`).
    stream
        Where the progress goes (default stderr).
    report
        Write ``report.md`` and the figures at the end.
    blas_threads
        Local pool: BLAS threads per worker, ``"auto"`` (usable CPUs // workers, at
        least 1) or a whole number (:mod:`flexctrl.study.blas_threads`).

    Raises
    ------
    SpecError
        If ``out`` holds another study, or ``resume`` finds nothing to resume.
    FlexctrlError
        If another study writes into ``out`` or the Dask scheduler cannot be reached.
    """
    start = time.monotonic()
    store = ResultStore(out)
    previous = store.read_study()
    if resume and previous is None:
        raise SpecError(f"nothing to resume: '{store.dir}' holds no study.json", key="--resume")
    if previous is not None and previous.get("study", {}).get("name") != spec.name:
        raise SpecError(
            f"'{store.dir}' holds the results of study '{previous.get('study', {}).get('name')}', "
            f"not '{spec.name}'; choose another --out",
            key="--out",
        )
    options = {
        "metrics": None if spec.metrics is None else list(spec.metrics),
        "keep_trajectories": spec.keep_trajectories,
        "decimation": spec.decimation,
    }
    backend = make_backend(workers, scheduler, client, blas_threads)
    backend.start()
    try:
        return _run(
            spec, store, previous, backend, options, resume, progress, stream, report, start
        )
    finally:
        backend.close()


def _open_session(store, spec, previous, backend, resume: bool, todo, skip):
    """``study.json`` with this session opened in it (written at once)."""
    document = previous or {"format": STUDY_FORMAT, "start": now_iso(), "sessions": []}
    session: dict[str, Any] = {
        "start": now_iso(),
        "end": None,
        "backend": backend.description,
        "resume": resume,
        "to_run": len(todo),
        "skipped": len(skip),
        "ok": 0,
        "failed": 0,
        "interrupted": False,
    }
    document.update(
        {"study": spec.to_dict(), "versions": versions(), "machine": machine(), "end": None}
    )
    document["sessions"].append(session)
    store.write_study(document)

    return document, session


def _close_session(store, spec, document, session, backend, interrupted: bool, start: float):
    """The table written, the shared fidelity choices listed, the session closed; the counts."""
    _, counts = store.write_table(columns=spec.columns, metrics=spec.metrics)
    if any("choice_from" in run.settings for run in spec.runs[:1]):
        from flexctrl.study.shared_choice import write_choices

        write_choices(
            store.dir,
            spec.runs,
            {run.run_id: store.read_record(run.run_id) for run in spec.runs},
        )
    session.update(
        {
            "end": now_iso(),
            "interrupted": interrupted,
            "backend": backend.description,
            "elapsed_s": round(time.monotonic() - start, 3),
            "parent_peak_memory_mb": peak_memory_mb(),
        }
    )
    document["end"] = session["end"]
    store.write_study(document)
    return counts


def _run(
    spec: StudySpec,
    store: ResultStore,
    previous: dict | None,
    backend: Any,
    options: dict,
    resume: bool,
    progress: str,
    stream: Any,
    report: bool,
    start: float,
) -> StudyResult:
    from flexctrl.study.progress import Progress

    with store:
        recorded = store.recorded()
        keep = ("ok", "failed") if resume else ("ok",)
        skip = {run.run_id for run in spec.runs if recorded.get(run.run_id) in keep}
        todo = [run for run in spec.runs if run.run_id not in skip]
        if isinstance(backend, LocalPoolBackend) and backend.workers > max(1, len(todo)):
            # no idle processes for a short resume
            backend = LocalPoolBackend(max(1, len(todo)), backend.blas_threads)
        store.write_plan(spec.runs)
        document, session = _open_session(store, spec, previous, backend, resume, todo, skip)
        bar = Progress(len(todo), skipped=len(skip), label=spec.name, mode=progress, stream=stream)
        interrupted = False
        warned: dict[str, int] = {}
        runs_warned = 0
        try:
            if todo:
                for run, result in backend.run(todo, spec.executor, options):
                    store.save(run, result)
                    for line in result.get("warnings") or ():
                        warned[line] = warned.get(line, 0) + 1
                    runs_warned += bool(result.get("warnings"))
                    session[result["status"]] += 1
                    bar.update(result["status"] == "ok")
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bar.close()
            counts = _close_session(store, spec, document, session, backend, interrupted, start)
        report_path = None
        if report and not interrupted:
            from flexctrl.study.report import write_report

            report_path = write_report(store.dir)
    counts.update({"ran": session["ok"] + session["failed"], "skipped": len(skip)})
    notes = (
        [
            f"{counts['extra']} record(s) in runs/ belong to no run of this study (left out of "
            "results.csv)"
        ]
        if counts.get("extra")
        else []
    ) + _warning_note(warned, runs_warned, report)
    return StudyResult(
        store.dir,
        counts,
        time.monotonic() - start,
        interrupted,
        report_path,
        backend.description,
        notes,
    )


def _warning_note(warned: dict[str, int], runs: int, report: bool) -> list[str]:
    """One line for the warnings of a session's runs: how many, the first, where the rest are."""
    if not warned:
        return []
    first = next(iter(warned))
    where = "report.md lists each" if report else "each run's record (runs/*.json) lists its own"
    return [
        f"{runs} run(s) warned ({len(warned)} distinct warning(s); {where}), the first: "
        f"{first if len(first) <= 200 else first[:197] + '...'}"
    ]
