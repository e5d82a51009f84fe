"""The celery backend (``PLANNER_QUEUE=celery``, ``PLANNER_BROKER=redis://...``, ``PLANNER_DB=postgresql+psycopg://...``):
the same task functions and the same runner (:class:`.runner.Slot`) in ``planner worker`` processes on any number of
machines; Redis carries the task messages (a job's id, nothing else), the database holds everything else.

Delivery:

- A message is acknowledged after its task has ended (``acks_late``), and given back when its worker is lost
  (``reject_on_worker_lost``); the broker's visibility timeout is above the longest allowed job
  (``job_timeout_s`` + :data:`VISIBILITY_MARGIN`), so a running job's message is never handed to a second worker
  while its first one lives.
- Completion is idempotent: a worker takes a job only while it is queued (one more attempt) and stores its end only
  while it is running in that attempt (:mod:`.transitions`), so a message delivered twice plans at most once more and
  stores one result; an execution is taken only once, ever (never re-run on a robot).
- A worker's pool runs threads, each driving one spawned worker process (the runner): cancellation (within
  :data:`.transitions.CANCEL_POLL` s of the request, read from the store), the time limit of a job and progress are
  the runner's, as in the local backend.
- Retries with back-off (1, 2, 4 ... 60 s) for transient failures only: the database unreachable when a task starts
  (the broker unreachable: its messages wait in the store, :class:`Publisher`); anything else fails the task with
  the planner's one-line error.
- Live samples of an execution (the page's 3D view): the worker running it writes them to a Redis stream on the
  broker's Redis, every API replica reads them there (:class:`.live.RedisLive`).
- Recovery (:class:`Keeper`, in every API replica): a running job whose worker stopped beating for
  :data:`.transitions.LEASE_S` s is queued again and its message sent again; an execution whose worker stopped
  beating fails "interrupted" and frees its robot; queued jobs whose messages the broker lost (a broker restarted
  without its data) are sent again once the broker's queue is empty.

The worker process (:func:`run_worker`, ``planner worker``) beats in the ``workers`` table: ``/metrics`` counts the
workers alive across the cluster.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import socket
import threading
from collections.abc import Callable
from typing import Any

from sqlalchemy import select, update
from sqlalchemy.exc import DBAPIError

from planner.frontends.service.config import ServiceConfig
from planner.frontends.service.live import RedisLive
from planner.frontends.service.store import Job, open_store
from planner.frontends.service.tasks.lifecycle import EXECUTION, JOB, Kind, Outcome
from planner.frontends.service.tasks.runner import Slot
from planner.frontends.service.tasks.split import Coordinator
from planner.frontends.service.tasks.transitions import HEARTBEAT_EVERY, LEASE_S, Transitions, now

log = logging.getLogger("planner.frontends.service")

#: The broker's queues: planning jobs and executions (a worker may serve one or both: ``planner worker --queues``).
PLAN_QUEUE = "plan"
EXECUTE_QUEUE = "execute"
#: The queue of each task (the Celery routes, and the publisher's own: no router lookup per message).
TASK_QUEUES = {"planner.plan_job": PLAN_QUEUE, "planner.plan_piece": PLAN_QUEUE, "planner.execute_job": EXECUTE_QUEUE,
               "planner.fit_piece": PLAN_QUEUE}  # (deprecated name of plan_piece, one release)
#: Seconds above the longest allowed job that a message stays invisible to other workers while unacknowledged.
VISIBILITY_MARGIN = 300.0
#: Seconds a queued job waits with the broker's queue empty before its message is sent again (a lost message).
RESEND_AFTER = 10.0
#: Seconds between the keeper's rounds.
KEEP_EVERY = 1.0
#: Retries of a task whose database is unreachable: back-off 1, 2, 4, ... 60 s, about an hour in all.
MAX_RETRIES = 64


def make_celery(cfg: ServiceConfig):
    """The Celery application of ``cfg`` (broker ``cfg.broker``; no result backend: results are in the store)."""
    from celery import Celery

    app = Celery("planner", broker=cfg.broker, set_as_current=False)
    app.conf.update(
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        task_acks_on_failure_or_timeout=True,
        worker_prefetch_multiplier=1,
        task_ignore_result=True,
        task_store_errors_even_if_ignored=False,
        broker_transport_options={"visibility_timeout": int(cfg.job_timeout_s + VISIBILITY_MARGIN)},
        broker_connection_retry_on_startup=True,
        broker_connection_timeout=2.0,
        task_default_queue=PLAN_QUEUE,
        task_routes={name: {"queue": q} for name, q in TASK_QUEUES.items()},
        worker_hijack_root_logger=False,
        worker_send_task_events=False,
        task_send_sent_event=False,
        worker_cancel_long_running_tasks_on_connection_loss=False,
    )
    _register(app)
    return app


# -- the worker side ----------------------------------------------------------------------------------------------
class WorkerContext:
    """What the tasks of one ``planner worker`` process share: the configuration, the store, one runner per pool
    thread."""

    def __init__(self, cfg: ServiceConfig, queues: str, concurrency: int, app=None):
        self.cfg = cfg
        self.queues = queues
        self.concurrency = concurrency
        self.app = app
        self.engine, _ = open_store(cfg.db_url)
        self.store = Transitions(self.engine)
        self.live = RedisLive(cfg.broker)  # executions' live samples, for every API replica
        self.stopping = threading.Event()
        self.started_at = now()
        self._local = threading.local()
        self._lock = threading.Lock()
        self.slots: list[Slot] = []
        self.coordinator = Coordinator(self.store, cfg.job_timeout_s, cfg.split_chords, self.stopping,
                                       self.send_pieces, lambda: self.store.workers_alive(PLAN_QUEUE)[0])

    def send_pieces(self, job_id: str, firsts: list[int]) -> None:
        """The messages of a split job's pieces (a piece whose message is lost is planned by the job's own worker)."""
        if not firsts or self.app is None:
            return
        try:
            with self.app.producer_or_acquire() as producer, producer.batch(max_size=len(firsts)):
                for first in firsts:
                    self.app.send_task("planner.plan_piece", args=[job_id, first], producer=producer, retry=False)
        except Exception as exc:
            log.warning("the broker did not take the pieces of job %s (%s); its own worker plans them", job_id, exc)

    def slot(self) -> Slot:
        """This pool thread's planning runner (its worker process kept warm between jobs)."""
        slot = getattr(self._local, "slot", None)
        if slot is None:
            slot = Slot(self.store, self.cfg.job_timeout_s, self.stopping)
            self._local.slot = slot
            with self._lock:
                self.slots.append(slot)
        return slot

    def busy(self) -> int:
        with self._lock:
            return sum(s.current is not None for s in self.slots)

    def beat(self) -> None:
        """This worker is alive (every HEARTBEAT_EVERY s, until it stops)."""
        while not self.stopping.is_set():
            with contextlib.suppress(Exception):  # the database away: the next beat tries again
                self.store.worker_beat(self.queues, self.concurrency, self.busy(), self.started_at)
            self.stopping.wait(HEARTBEAT_EVERY)
        with contextlib.suppress(Exception):
            self.store.worker_gone()

    def close(self) -> None:
        self.stopping.set()
        with self._lock:
            slots = list(self.slots)
        for s in slots:
            s.stop_process()


_context: WorkerContext | None = None


def _ctx() -> WorkerContext:
    if _context is None:
        raise RuntimeError("the planner's Celery tasks run in `planner worker` processes only")
    return _context


def _register(app) -> None:
    from celery.exceptions import Reject

    transient = (DBAPIError,)
    options: dict[str, Any] = dict(bind=True, acks_late=True, reject_on_worker_lost=True, autoretry_for=transient,
                                   retry_backoff=1, retry_backoff_max=60, retry_jitter=False,
                                   max_retries=MAX_RETRIES)

    @app.task(name="planner.plan_job", **options)
    def plan_job_task(self, job_id: str) -> str:
        ctx = _ctx()
        claimed = ctx.store.claim_job(job_id)
        if claimed is None:  # taken by another delivery, cancelled, or ended: nothing to do (idempotent)
            return "skipped"
        ctx.coordinator.run_job(ctx.slot(), *claimed)  # (split across the workers if it pays: .split)
        if ctx.stopping.is_set() and ctx.store.state(JOB, job_id) == "queued":  # handed back by a stopping worker
            raise Reject("the worker is stopping", requeue=True)
        return "ran"

    @app.task(name="planner.plan_piece", **options)
    def plan_piece_task(self, job_id: str, first: int) -> str:
        ctx = _ctx()
        return ctx.coordinator.run_piece(ctx.slot(), job_id, int(first))

    @app.task(name="planner.fit_piece", **options)
    def fit_piece_task(self, job_id: str, first: int) -> str:
        """Deprecated name of "planner.plan_piece" (messages of a coordinator of the previous release), kept for one
        release."""
        log.warning('task "planner.fit_piece" is deprecated: it is "planner.plan_piece" (upgrade every worker)')
        return plan_piece_task.run(job_id, first)

    @app.task(name="planner.execute_job", **options)
    def execute_job_task(self, execution_id: str) -> str:
        ctx = _ctx()
        claimed = ctx.store.claim_execution(execution_id, ctx.cfg.robots)
        if claimed is None:  # taken once already (never run twice on a robot), stopped, or ended
            return "skipped"
        slot = Slot(ctx.store, ctx.cfg.job_timeout_s, ctx.stopping, name="planner-exec", live=ctx.live)
        with ctx._lock:
            ctx.slots.append(slot)
        try:
            slot.run(EXECUTION, *claimed)
        finally:
            slot.stop_process(kill=True)
            with ctx._lock:
                ctx.slots.remove(slot)
        return "ran"


def worker_queues(cfg: ServiceConfig, queues: str) -> list[str]:
    """The queues of ``planner worker --queues``; PlannerError if the configuration is not the celery backend's or a
    queue is unknown."""
    from planner.errors import PlannerError

    if cfg.queue != "celery":
        raise PlannerError("planner worker needs PLANNER_QUEUE=celery and PLANNER_BROKER (redis://HOST:PORT/0)")
    names = [q.strip() for q in queues.split(",") if q.strip()]
    unknown = sorted(set(names) - {PLAN_QUEUE, EXECUTE_QUEUE})
    if not names or unknown:
        raise PlannerError(f"--queues: {', '.join(unknown) or 'none given'}; the queues are {PLAN_QUEUE} and "
                           f"{EXECUTE_QUEUE}")
    return names


def run_worker(cfg: ServiceConfig, concurrency: int, queues: str, loglevel: str = "warning") -> None:
    """``planner worker``: a Celery worker (thread pool of ``concurrency``, each thread one worker process) on
    ``queues`` ("plan", "execute" or both, comma-separated). Ends on SIGTERM/SIGINT: running jobs are put back in the
    queue, running executions stopped."""
    global _context
    from celery import signals

    names = worker_queues(cfg, queues)
    # batch work, the whole process (its bookkeeping too: claims, heartbeats, plans stored): on a machine shared with
    # API replicas their requests come first (`bench_scale.py --only replicas`, 2 replicas and 2 workers on 2 cores,
    # quiet machine: p99 submit 85.9 -> 50.3 and 62.7 ms); its worker processes inherit the niceness and add none
    with contextlib.suppress(OSError):
        os.nice(cfg.worker_nice)
    app = make_celery(cfg)
    _context = WorkerContext(cfg, ",".join(names), concurrency, app)
    ctx = _context
    threading.Thread(target=ctx.beat, name="worker-heartbeat", daemon=True).start()

    @signals.worker_shutting_down.connect(weak=False)
    def _stopping(**_kw) -> None:
        ctx.stopping.set()

    hostname = f"planner-{os.getpid()}@{socket.gethostname()}"
    try:
        app.worker_main(["worker", "--pool=threads", f"--concurrency={concurrency}", f"--queues={','.join(names)}",
                         f"--loglevel={loglevel.upper()}", "--without-gossip", "--without-mingle",
                         "--without-heartbeat", f"--hostname={hostname}"])
    finally:
        ctx.close()


# -- the API side -------------------------------------------------------------------------------------------------
class Publisher(threading.Thread):
    """Task messages sent from a thread of their own (a submit never waits for the broker). A message that cannot be
    sent (the broker unreachable) is dropped here: its task waits in the store, and the :class:`Keeper` sends it
    again once the broker answers."""

    def __init__(self, app):
        super().__init__(name="planner-publisher", daemon=True)
        self.app = app
        self.pending: queue.Queue = queue.Queue()
        self.sent = 0
        self.declared: set[str] = set()  # queues a message of this publisher reached

    def put(self, name: str, task_ids: list[str]) -> None:
        for task_id in task_ids:
            self.pending.put((name, task_id))

    def run(self) -> None:
        while True:
            item = self.pending.get()
            if item is None:
                return
            batch = [item]
            with contextlib.suppress(queue.Empty):
                while len(batch) < 500:
                    nxt = self.pending.get_nowait()
                    if nxt is None:
                        self.pending.put(None)
                        break
                    batch.append(nxt)
            try:
                # one pipeline of LPUSHes for the batch (kombu's publish batch): one round trip to Redis, where a
                # message each took a third of the API replica's CPU per submit and held the event loop's GIL
                # the queue named (no router lookup), and not declared again once a message reached it: kombu's
                # declaration check copied the queue's entity for every message (with the lookup, 0.30 -> 0.17 ms of
                # CPU per message, all of it taken from the event loop's GIL)
                with self.app.producer_or_acquire() as producer, producer.batch(max_size=len(batch)):
                    for name, task_id in batch:
                        to = TASK_QUEUES[name]
                        self.app.send_task(name, args=[task_id], producer=producer, retry=False, queue=to,
                                           declare=[] if to in self.declared else None)
                self.declared.update(TASK_QUEUES[name] for name, _ in batch)
                self.sent += len(batch)
            except Exception as exc:  # the broker away: the keeper sends them again
                log.warning("the broker did not take %d task messages (%s); sent again later", len(batch), exc)

    def stop(self) -> None:
        self.pending.put(None)
        self.join(5.0)


class Keeper(threading.Thread):
    """Recovery by heartbeats, every :data:`KEEP_EVERY` s, in each API replica (each change a conditional update:
    replicas never do one twice): jobs of dead workers queued again (and sent), executions of dead workers failed,
    queued jobs whose messages were lost sent again."""

    def __init__(self, backend: CeleryBackend):
        super().__init__(name="planner-keeper", daemon=True)
        self.backend = backend
        self.stopping = threading.Event()

    def run(self) -> None:
        while not self.stopping.wait(KEEP_EVERY):
            try:
                self.keep()
            except Exception as exc:  # the database or the broker away: the next round tries again
                log.debug("keeper round failed: %s", exc)

    def keep(self) -> None:
        b = self.backend
        stale = now() - LEASE_S
        if b.store.any_stale(stale):  # (one read a round; the writes only when there is something to recover)
            got = b.store.recover(stale, b.cfg.max_attempts, "its worker stopping to answer",
                                  "its workers stopping to answer")
            if got["requeued_ids"]:
                b.publisher.put("planner.plan_job", got["requeued_ids"])
        if b.queue_depth() == 0:
            stale = now() - RESEND_AFTER
            unsent = (Job.state == "queued") & (Job.created_at < stale) & (
                (Job.heartbeat_at < stale) | Job.heartbeat_at.is_(None))
            with b.store.engine.connect() as conn:  # (one read; the write only when it finds one, as above)
                if not conn.scalar(select(select(Job.id).where(unsent).exists())):
                    return
            with b.store.write_lock, b.store.engine.begin() as conn:
                ids = [r[0] for r in conn.execute(update(Job).where(unsent).values(heartbeat_at=now())
                                                  .returning(Job.id))]
            if ids:
                log.warning("%d queued jobs had no message in the broker; sent again", len(ids))
                b.publisher.put("planner.plan_job", ids)

    def stop(self) -> None:
        self.stopping.set()
        self.join(5.0)


class CeleryBackend:
    """The API replica's side of the celery backend: stores tasks, sends their messages, reads the cluster's
    figures."""

    name = "celery"

    def __init__(self, store: Transitions, cfg: ServiceConfig, on_finish: Callable[[Kind, Outcome, float], None]):
        self.store = store
        self.cfg = cfg
        self.app = make_celery(cfg)
        self.publisher = Publisher(self.app)
        self.keeper = Keeper(self)
        self.live = RedisLive(cfg.broker)  # the workers' executions' live samples
        import redis

        #: The broker's Redis, for its queue's depth (one connection kept: kombu's opened one per look).
        self.broker = redis.Redis.from_url(str(cfg.broker), socket_timeout=2.0, socket_connect_timeout=2.0)

    def start(self) -> dict:
        self.publisher.start()
        self.keeper.start()
        return {}

    def stop(self) -> None:
        self.keeper.stop()
        self.publisher.stop()
        with contextlib.suppress(Exception):
            self.broker.close()

    def submitted(self, job_ids: list[str]) -> None:
        self.publisher.put("planner.plan_job", job_ids)

    def cancel_job(self, job_id: str) -> str | None:
        return self.store.cancel_job(job_id)

    def start_execution(self, values: dict) -> None:
        self.store.create_execution(values)
        self.publisher.put("planner.execute_job", [values["id"]])

    def stop_execution(self, execution_id: str, reason: str = "stopped by the operator") -> bool:
        return self.store.stop_execution(execution_id, reason)

    def workers(self) -> tuple[int, int]:
        """Worker slots alive and busy across the cluster (the workers' heartbeats)."""
        return self.store.workers_alive()

    def queue_depth(self) -> int:
        """Planning messages waiting in the broker's queue (-1: the broker does not answer)."""
        try:
            return int(self.broker.llen(PLAN_QUEUE))
        except Exception:
            return -1
