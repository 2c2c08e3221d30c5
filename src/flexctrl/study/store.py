"""The result folder of a study: per-run records written atomically, the table rebuilt from them.

Layout of ``DIR``::

    study.json        versions, machine, the study's settings, one entry per session
    plan.jsonl        the current grid, one JSON line per run: run_id, index, coords, settings
    runs/<id>.json    one record per finished run (status ok or failed)
    runs/<id>.npz     its trajectories, compressed and decimated (numpy, no pickle)
    results.csv       one row per recorded run of the plan, in grid order
    report.md, figures/*.png
    .lock             held (flock) while a study writes into DIR

Who writes: the parent process, as results arrive.  Workers return plain data
(metrics and decimated arrays) and never touch ``DIR``, so a Dask worker on a
machine without the study's folder works, there is exactly one writer (no
races between workers, one place for atomicity), and a worker killed
mid-run leaves nothing behind.  The price is that trajectories travel through
the pool's pipe; decimate them when they are large.

Every file is written to a hidden temporary name in the same folder
(``.<name>.<pid>.tmp``) and renamed over the target with :func:`os.replace`,
so a reader sees either the previous file or the new one, never a part, even
if the writer is killed at any instant.  The npz of a run is written before
its record, so a record always points to a complete trajectory file.
``results.csv`` is rebuilt from the records (never appended to), so a kill at
any moment loses only runs in flight.  ``study.json``, ``plan.jsonl`` and
``results.csv`` are also fsynced; per-run files are not (an fsync cost 3 ms
per file here, most of the parent's work per run): after a power cut or an
OS crash a record may be empty, and an unreadable record counts as "not run",
so the run is simply run again.
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import json
import math
import os
import warnings
import zipfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import suppress
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import FlexctrlError

RECORD_FORMAT = 1
FIXED_BEFORE = ("run_id",)
FIXED_AFTER_COORDS = ("seed", "status", "error")
FIXED_TAIL = ("wall_time_s", "peak_memory_mb", "bytes_written", "worker")
TEXT_COLUMNS = ("run_id", "status", "error", "worker")


def now_iso() -> str:
    """The current time, ISO 8601 with the local offset, to the second."""
    return _dt.datetime.now().astimezone().isoformat(timespec="seconds")


def atomic_write(
    path: Path, write: Callable[[io.BufferedWriter], None] | bytes, *, fsync: bool = True
) -> int:
    """Write ``path`` atomically (temporary file + ``os.replace``); returns the bytes written.

    ``fsync`` also forces the data to disk before the rename (durable across a
    power cut, not only across a kill of the process).
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            if isinstance(write, (bytes, bytearray)):
                fh.write(write)
            else:
                write(fh)
            fh.flush()
            if fsync:
                os.fsync(fh.fileno())
        size = tmp.stat().st_size
        os.replace(tmp, path)
    except BaseException:
        with suppress(OSError):
            tmp.unlink()
        raise
    return size


def _json_value(value: Any) -> Any:
    """Non-finite floats become None (JSON has no NaN)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def cell(value: Any) -> str:
    """One CSV cell: '' for None, shortest round-trip text for floats, JSON for lists."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    if isinstance(value, (list, tuple, dict)):
        return json.dumps(value, separators=(",", ":"))
    return str(value).replace("\r", " ").replace("\n", " ")


class Table:
    """``results.csv`` read back: columns and typed rows.

    A column whose every non-empty cell is a number is read as floats (``seed``
    as int); empty cells are None.
    """

    def __init__(self, columns: list[str], rows: list[dict[str, Any]]):
        self.columns = columns
        self.rows = rows

    def __len__(self) -> int:
        return len(self.rows)

    def column(self, name: str) -> list[Any]:
        """The values of one column."""
        return [row.get(name) for row in self.rows]

    def to_pandas(self):
        """The table as a ``pandas.DataFrame`` (pandas is an optional dependency)."""
        import pandas as pd

        return pd.DataFrame(self.rows, columns=self.columns)

    @classmethod
    def read(cls, path: Path) -> Table:
        """Read a ``results.csv``."""
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            columns = next(reader, [])
            raw = [dict(zip(columns, row)) for row in reader]
        typed: dict[str, Callable[[str], Any]] = {}
        for name in columns:
            if name in TEXT_COLUMNS:
                typed[name] = str
                continue
            try:
                for row in raw:
                    if row.get(name, ""):
                        float(row[name])
                typed[name] = int if name == "seed" else float
            except ValueError:
                typed[name] = str
        rows = [
            {
                name: (typed[name](row[name]) if row.get(name, "") != "" else None)
                for name in columns
            }
            for row in raw
        ]
        for record in rows:
            record["error"] = record.get("error") or ""
        return cls(columns, rows)


class ResultStore:
    """A study's result folder (see the module docstring).

    Parameters
    ----------
    directory
        The folder; created by :meth:`open`.
    """

    def __init__(self, directory: str | os.PathLike):
        self.dir = Path(directory)
        self.runs_dir = self.dir / "runs"
        self._lock_fh: io.TextIOWrapper | None = None

    # -- paths -----------------------------------------------------------------------
    @property
    def study_path(self) -> Path:
        return self.dir / "study.json"

    @property
    def plan_path(self) -> Path:
        return self.dir / "plan.jsonl"

    @property
    def table_path(self) -> Path:
        return self.dir / "results.csv"

    def record_path(self, run_id: str) -> Path:
        return self.runs_dir / f"{run_id}.json"

    def trajectory_path(self, run_id: str) -> Path:
        return self.runs_dir / f"{run_id}.npz"

    # -- writing session -------------------------------------------------------------
    def open(self) -> ResultStore:
        """Create the folders, take the lock and remove temporary files left by a killed writer.

        Raises
        ------
        FlexctrlError
            If another study holds the lock on this folder.
        """
        self.runs_dir.mkdir(parents=True, exist_ok=True)
        lock = self._lock_fh = open(self.dir / ".lock", "a+")
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no lock
            pass
        else:
            try:
                fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                lock.close()
                self._lock_fh = None
                raise FlexctrlError(
                    f"another flexctrl study is writing into '{self.dir}'; wait for it or choose "
                    "another --out"
                ) from None
        for folder in (self.dir, self.runs_dir):
            for stale in folder.glob(".*.tmp"):
                with suppress(OSError):
                    stale.unlink()
        return self

    def close(self) -> None:
        """Release the lock."""
        if self._lock_fh is not None:
            self._lock_fh.close()
            self._lock_fh = None

    def __enter__(self) -> ResultStore:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    # -- study.json and plan ---------------------------------------------------------
    def read_study(self) -> dict[str, Any] | None:
        """``study.json`` or None."""
        if not self.study_path.is_file():
            return None
        return json.loads(self.study_path.read_text())

    def write_study(self, document: Mapping[str, Any]) -> None:
        atomic_write(self.study_path, (json.dumps(document, indent=2, default=str) + "\n").encode())

    def write_plan(self, runs: Iterable[Any]) -> None:
        """Write ``plan.jsonl`` from :class:`~flexctrl.study.plan.RunSpec` objects."""

        def write(fh):
            for run in runs:
                line = {
                    "run_id": run.run_id,
                    "index": run.index,
                    "coords": run.coordinates,
                    "settings": run.settings,
                }
                fh.write((json.dumps(line, separators=(",", ":")) + "\n").encode())

        atomic_write(self.plan_path, write)

    def iter_plan(self) -> Iterator[dict[str, Any]]:
        """The lines of ``plan.jsonl`` (empty if there is none)."""
        if not self.plan_path.is_file():
            return
        with open(self.plan_path) as fh:
            for line in fh:
                if line.strip():
                    yield json.loads(line)

    # -- records -----------------------------------------------------------------------
    def read_record(self, run_id: str) -> dict[str, Any] | None:
        """The record of one run, or None if absent or unreadable (with a warning)."""
        path = self.record_path(run_id)
        try:
            return json.loads(path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as exc:
            warnings.warn(f"ignoring unreadable run record '{path}': {exc}", stacklevel=2)
            return None

    def recorded(self) -> dict[str, str]:
        """Status (``ok``/``failed``) of every run with a record in ``runs/``."""
        status = {}
        for path in self.runs_dir.glob("*.json"):
            record = self.read_record(path.stem)
            if record is not None and record.get("status") in ("ok", "failed"):
                status[path.stem] = record["status"]
        return status

    def save(self, run: Any, result: Mapping[str, Any]) -> dict[str, Any]:
        """Write one run's trajectories (if any), then its record; returns the record.

        ``result`` is what :func:`flexctrl.study.runner.execute_run` returned.
        """
        arrays = result.get("trajectories") or {}
        npz_bytes = 0
        if arrays:
            npz_bytes = atomic_write(
                self.trajectory_path(run.run_id),
                lambda fh: np.savez_compressed(fh, **arrays),
                fsync=False,
            )
        else:
            with suppress(FileNotFoundError):
                self.trajectory_path(run.run_id).unlink()
        record = {
            "format": RECORD_FORMAT,
            "run_id": run.run_id,
            "index": run.index,
            "coords": run.coordinates,
            "settings": run.settings,
            "status": result["status"],
            "error": result.get("error", ""),
            "warnings": list(result.get("warnings") or []),
            "metrics": {k: _json_value(v) for k, v in (result.get("metrics") or {}).items()},
            "wall_time_s": result.get("wall_time_s"),
            "peak_memory_mb": result.get("peak_memory_mb"),
            "bytes_written": 0,
            "trajectories": self.trajectory_path(run.run_id).name if arrays else None,
            "samples": int(max((len(a) for a in arrays.values()), default=0)),
            "worker": result.get("worker", ""),
            "finished_at": now_iso(),
        }
        text = b""
        for _ in range(4):  # the record counts its own size: iterate to the fixed point
            text = (json.dumps(record, indent=1, allow_nan=False) + "\n").encode()
            if record["bytes_written"] == npz_bytes + len(text):
                break
            record["bytes_written"] = npz_bytes + len(text)
        atomic_write(self.record_path(run.run_id), text, fsync=False)
        return record

    def load_trajectories(self, run_id: str) -> dict[str, np.ndarray]:
        """The stored trajectories of a run (empty if none); never unpickles."""
        path = self.trajectory_path(run_id)
        if not path.is_file():
            return {}
        try:
            with np.load(path, allow_pickle=False) as data:
                return {name: data[name] for name in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            warnings.warn(f"ignoring unreadable trajectory file '{path}': {exc}", stacklevel=2)
            return {}

    # -- the table ---------------------------------------------------------------------
    def write_table(
        self, columns: Iterable[str] | None = None, metrics: Iterable[str] | None = None
    ) -> tuple[Path, dict[str, int]]:
        """Rebuild ``results.csv`` from the records of the plan's runs, in grid order.

        Parameters
        ----------
        columns
            Coordinate columns (default: every coordinate of the plan, in order).
        metrics
            Metric columns (default: every metric recorded, in order of first appearance).

        Returns
        -------
        path, counts
            ``counts`` has ``ok``, ``failed``, ``pending`` (planned, no record) and
            ``extra`` (records of runs not in the plan, left out).
        """
        plan_ids = []
        coord_columns: dict[str, None] = dict.fromkeys(columns or ())
        for line in self.iter_plan():
            plan_ids.append(line["run_id"])
            if columns is None:
                coord_columns.update(dict.fromkeys(line["coords"]))
        metric_columns: dict[str, None] = dict.fromkeys(metrics or ())
        counts = {"ok": 0, "failed": 0, "pending": 0, "extra": 0}
        if metrics is None:
            for rid in plan_ids:
                record = self.read_record(rid)
                if record is not None:
                    metric_columns.update(dict.fromkeys(record.get("metrics") or {}))
        header = (
            list(FIXED_BEFORE)
            + list(coord_columns)
            + list(FIXED_AFTER_COORDS)
            + list(metric_columns)
            + list(FIXED_TAIL)
        )

        def write(fh):
            text = io.TextIOWrapper(fh, newline="", encoding="utf-8")
            out = csv.writer(text, lineterminator="\n")
            out.writerow(header)
            for rid in plan_ids:
                record = self.read_record(rid)
                if record is None:
                    counts["pending"] += 1
                    continue
                counts[record["status"]] = counts.get(record["status"], 0) + 1
                coords = record.get("coords", {})
                values = record.get("metrics") or {}
                row = [rid] + [cell(coords.get(c)) for c in coord_columns]
                row += [
                    cell(record["settings"].get("seed")),
                    record["status"],
                    cell(record.get("error", "")),
                ]
                row += [cell(values.get(m)) for m in metric_columns]
                row += [
                    cell(_round(record.get("wall_time_s"), 6)),
                    cell(_round(record.get("peak_memory_mb"), 1)),
                    cell(record.get("bytes_written")),
                    cell(record.get("worker", "")),
                ]
                out.writerow(row)
            text.flush()
            text.detach()

        atomic_write(self.table_path, write)
        planned = set(plan_ids)
        counts["extra"] = sum(1 for p in self.runs_dir.glob("*.json") if p.stem not in planned)
        return self.table_path, counts

    def read_table(self) -> Table:
        """``results.csv`` as a :class:`Table`."""
        return Table.read(self.table_path)


def _round(value: Any, digits: int) -> Any:
    return round(value, digits) if isinstance(value, float) and math.isfinite(value) else value
