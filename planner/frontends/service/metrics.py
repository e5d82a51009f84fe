"""Prometheus text exposition (format 0.0.4) of the service: jobs by state, queue depth, planning times; executions by
state, running per robot, execution times, failures by kind (protective stop, connection lost, ...)."""

from __future__ import annotations

import threading

#: Upper bounds of the planning-time histogram buckets, s.
BUCKETS = (0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 300.0, 1800.0)
#: Upper bounds of the execution-time histogram buckets, s (a run on a robot: seconds to hours).
EXECUTION_BUCKETS = (1.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0, 7200.0, 14400.0)


class Histogram:
    """A cumulative histogram (thread-safe)."""

    def __init__(self, buckets: tuple[float, ...] = BUCKETS):
        self.buckets = buckets
        self.counts = [0] * len(buckets)
        self.count = 0
        self.sum = 0.0
        self._lock = threading.Lock()

    def observe(self, value: float) -> None:
        with self._lock:
            self.count += 1
            self.sum += value
            for i, b in enumerate(self.buckets):
                if value <= b:
                    self.counts[i] += 1

    def lines(self, name: str) -> list[str]:
        with self._lock:
            out = [f'{name}_bucket{{le="{b:g}"}} {c}' for b, c in zip(self.buckets, self.counts, strict=True)]
            out += [f'{name}_bucket{{le="+Inf"}} {self.count}', f"{name}_sum {self.sum:.6f}",
                    f"{name}_count {self.count}"]
        return out


class Metrics:
    """What the service counts besides the database's figures."""

    def __init__(self) -> None:
        self.planning = Histogram()
        self.submitted = 0
        self.finished: dict[str, int] = {}
        self.execution_time = Histogram(EXECUTION_BUCKETS)
        self.executions_finished: dict[str, int] = {}
        self.execution_failures: dict[str, int] = {}
        self._lock = threading.Lock()

    def count_submitted(self) -> None:
        with self._lock:
            self.submitted += 1

    def count_finished(self, state: str, planning_s: float | None = None) -> None:
        with self._lock:
            self.finished[state] = self.finished.get(state, 0) + 1
        if planning_s is not None:
            self.planning.observe(planning_s)

    def count_execution(self, state: str, seconds: float | None, kind: str | None = None) -> None:
        """An execution that ended in ``state`` after ``seconds`` (request to end; None: not known, e.g. one a
        restart failed), failed with ``kind`` (the driver's: "protective stop", "connection lost", ...)."""
        with self._lock:
            self.executions_finished[state] = self.executions_finished.get(state, 0) + 1
            if state == "failed":
                kind = kind or "unknown"
                self.execution_failures[kind] = self.execution_failures.get(kind, 0) + 1
        if seconds is not None:
            self.execution_time.observe(seconds)

    def text(self, by_state: dict[str, int], workers_alive: int, workers_busy: int,
             executions: dict[str, int] | None = None, running: dict[str, int] | None = None,
             queue_depth: int | None = None) -> str:
        """The exposition text; ``by_state`` counts the stored jobs and ``executions`` the stored executions by state
        (every state present, zeros included), ``running`` the active executions of each configured robot,
        ``queue_depth`` the planning tasks waiting in the queue (default: the queued jobs)."""
        lines = ["# HELP planner_jobs Jobs in the store by state.", "# TYPE planner_jobs gauge"]
        lines += [f'planner_jobs{{state="{s}"}} {n}' for s, n in by_state.items()]
        lines += ["# HELP planner_queue_depth Planning tasks waiting for a worker.", "# TYPE planner_queue_depth gauge",
                  f"planner_queue_depth {by_state.get('queued', 0) if queue_depth is None else queue_depth}",
                  "# HELP planner_workers Planning worker processes alive.", "# TYPE planner_workers gauge",
                  f"planner_workers {workers_alive}",
                  "# HELP planner_workers_busy Planning worker processes running a job.",
                  "# TYPE planner_workers_busy gauge", f"planner_workers_busy {workers_busy}",
                  "# HELP planner_jobs_submitted_total Jobs accepted since the service started.",
                  "# TYPE planner_jobs_submitted_total counter", f"planner_jobs_submitted_total {self.submitted}",
                  "# HELP planner_jobs_finished_total Jobs that reached a final state since the service started.",
                  "# TYPE planner_jobs_finished_total counter"]
        with self._lock:
            lines += [f'planner_jobs_finished_total{{state="{s}"}} {n}' for s, n in sorted(self.finished.items())]
        lines += ["# HELP planner_planning_seconds Planning time of finished jobs (worker, parse to saved plan).",
                  "# TYPE planner_planning_seconds histogram", *self.planning.lines("planner_planning_seconds")]
        lines += ["# HELP planner_executions Executions in the store by state.", "# TYPE planner_executions gauge"]
        lines += [f'planner_executions{{state="{s}"}} {n}' for s, n in (executions or {}).items()]
        lines += ["# HELP planner_executions_running Active executions (starting, running or stopping) by robot.",
                  "# TYPE planner_executions_running gauge"]
        lines += [f'planner_executions_running{{robot="{_label(r)}"}} {n}' for r, n in (running or {}).items()]
        lines += ["# HELP planner_executions_finished_total Executions that ended since the service started, by state.",
                  "# TYPE planner_executions_finished_total counter"]
        with self._lock:
            lines += [f'planner_executions_finished_total{{state="{s}"}} {n}'
                      for s, n in sorted(self.executions_finished.items())]
            lines += ["# HELP planner_execution_failures_total Executions that failed since the service started, by "
                      "the kind of failure (protective stop, emergency stop, connection lost, period overrun, not "
                      "ready, interrupted, internal, ...).",
                      "# TYPE planner_execution_failures_total counter"]
            lines += [f'planner_execution_failures_total{{kind="{_label(k)}"}} {n}'
                      for k, n in sorted(self.execution_failures.items())]
        lines += ["# HELP planner_execution_seconds Time of ended executions, from the request to the end (controller, "
                  "connection, approach and run).", "# TYPE planner_execution_seconds histogram",
                  *self.execution_time.lines("planner_execution_seconds")]
        return "\n".join(lines) + "\n"


def _label(value: str) -> str:
    """A label value escaped for the text format (backslash, double quote, newline)."""
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
