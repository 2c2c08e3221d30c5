"""Batch studies: a grid of runs over payloads, configurations, controllers and settings.

``load_study(path)`` reads and validates a study file into a :class:`StudySpec`
with every run expanded (:mod:`flexctrl.study.study_file`); ``run_study(spec, out)``
runs what is not yet recorded in ``out`` on a local process pool or a Dask
cluster (:mod:`flexctrl.study.runner`), writing one record per run as it
finishes (:mod:`flexctrl.study.store`); ``write_report(out)`` draws the report
from the files alone (:mod:`flexctrl.study.report`).  What one run does is an
*executor* named by the study (:mod:`flexctrl.study.executors`).  The file
format and the folder layout are described in ``docs/explanation/studies.md``.
"""

from flexctrl.study.outputs import RunOutput, per_worker_cache
from flexctrl.study.plan import ReportSpec, RunSpec, StudySpec
from flexctrl.study.registry import executor_names, get_executor, register_executor
from flexctrl.study.report import write_report
from flexctrl.study.run_execution import execute_run
from flexctrl.study.runner import StudyResult, run_study
from flexctrl.study.store import ResultStore, Table
from flexctrl.study.study_file import load_study

__all__ = [
    "RunOutput",
    "executor_names",
    "get_executor",
    "per_worker_cache",
    "register_executor",
    "write_report",
    "StudyResult",
    "execute_run",
    "run_study",
    "ReportSpec",
    "RunSpec",
    "StudySpec",
    "load_study",
    "ResultStore",
    "Table",
]
