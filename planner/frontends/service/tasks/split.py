"""One large job split across the workers of the celery backend: its moves planned in pieces on several workers and
joined where the whole sequence is (placement, spin, the robot check and the arm configurations along all of it).

The worker that takes the job's message is its coordinator (:func:`run_job`): it holds the job (its heartbeats,
its progress, its time limit, its cancellation), finds the job's pieces (:func:`planner.plan.plan_pieces`: one per
worker slot alive, consecutive cutting passes balanced by CAM chords and by what chaining the frames of the moves
before a piece costs it; a parse of the file), and if the job is large enough (``PLANNER_SPLIT_CHORDS``: CAM chords
of passes whose tool axis varies, a chord of a constant axis counting 0.115, :data:`planner.plan.PIECE_COST`; two
pieces, two worker slots alive) stores its pieces (:class:`~planner.frontends.service.store.JobChunk`) and sends
one message per piece ("planner.plan_piece"). Any worker takes a piece (:func:`run_piece`:
:func:`planner.plan.plan_piece`, its planned moves stored in the database with the piece marked done, in one
transaction); the coordinator plans the pieces no other worker has taken yet itself, so a job
never waits for a busy queue and coordinators never wait for each other, then joins them (:func:`planner.plan`,
``pieces=``) and stores the job's end as any job's (conditionally: :meth:`.transitions.Transitions.finish`). The
plan is the one a single process makes, export for export, byte for byte: every piece chains the tool frames of the
moves before it exactly as one process does (their fits and frames, no time law), so its first move starts from the
same bits.

Where it pays (``PLANNER_SPLIT_CHORDS``, default :data:`~planner.frontends.service.config.SPLIT_CHORDS`): beyond its
work a piece costs its worker a parse of the file, the chain, its moves written as bytes (0.8 s for the larger of the
NX job's two pieces), and the coordinator about 0.5 s (the pieces found, the messages, its polling, the pieces' moves
read back and the join).

- Cancellation: a piece's runner reads the job's row like the job's own (every :data:`.transitions.CANCEL_POLL` s)
  and kills its process once the job has ended.
- A piece that fails fails the job with its one-line error.
- A worker killed mid-piece: the piece's heartbeats stop; after :data:`.transitions.LEASE_S` s the coordinator takes
  it over and plans it (the broker's redelivery of the piece's unacknowledged message, after its visibility timeout,
  then finds it done). A coordinator killed: the job is queued again as any job (:class:`.celery_backend.Keeper`);
  its next attempt keeps the pieces already planned.
- A piece's message delivered twice, or the job ended: nothing is planned again (the piece is taken only while
  queued, its end stored only by its take).

Why the join is the coordinator's and not a task sent when the last piece ends (a Celery chord): the job's row needs
a live holder while its pieces wait in a busy queue (else it is taken for dead after LEASE_S s and started again),
and a chord needs a result backend this service does not run.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import replace

from planner.frontends.service.tasks.functions import PlanSpec
from planner.frontends.service.tasks.lifecycle import JOB, Outcome, Progress, failed
from planner.frontends.service.tasks.runner import Slot
from planner.frontends.service.tasks.transitions import CANCEL_POLL, HEARTBEAT_EVERY, LEASE_S, Transitions, now

#: Files smaller than this are never split (no parse to find their batches): bytes. A CAM chord takes 10 to 45 bytes
#: in the shared APT/CLSF and G-code files; the smallest job split by default has 2 x 8192 chords.
SPLIT_MIN_BYTES = 64 * 1024


def may_split(spec: PlanSpec, split_chords: int) -> bool:
    """The job is a file large enough to look for its pieces (``split_chords`` 0: never split)."""
    return (split_chords > 0 and spec.input_kind == "file" and spec.step == "plan" and spec.pieces is None
            and spec.input_data is not None and len(spec.input_data) >= SPLIT_MIN_BYTES)


def split_note(pieces: list[dict]) -> str:
    """The job's note on how it was split: pieces, chords, workers, the pieces' times, pieces taken over."""
    holders = {p["holder"] for p in pieces}
    again = sum(p["takes"] > 1 for p in pieces)
    text = (f"split: planned in {len(pieces)} pieces by {len(holders)} workers (CAM chords "
            f"{', '.join(str(p['chords']) for p in pieces)}; piece s "
            f"{', '.join('%.1f' % (p['seconds'] or 0.0) for p in pieces)})")  # noqa: UP031
    return text + (f"; {again} taken over from a worker that stopped answering" if again else "")


class Coordinator:
    """The worker side a split job needs: the store, this worker's slot, sending piece messages, and the worker
    slots alive across the cluster."""

    def __init__(self, store: Transitions, job_timeout_s: float, split_chords: int, stopping,
                 send: Callable[[str, list[int]], None], slots_alive: Callable[[], int]):
        self.store = store
        self.job_timeout_s = job_timeout_s
        self.split_chords = split_chords
        self.stopping = stopping
        self.send = send
        self.slots_alive = slots_alive

    # -- the job's own worker -----------------------------------------------------------------------------------------
    def run_job(self, slot: Slot, job_id: str, attempt: int, spec: PlanSpec) -> None:
        """Run the claimed job: split across the workers if it pays, else whole in ``slot``."""
        if not may_split(spec, self.split_chords) or self.slots_alive() < 2:
            slot.run(JOB, job_id, attempt, spec)
            return
        deadline = time.monotonic() + self.job_timeout_s
        found = slot.ask(job_id, attempt, replace(spec, step="pieces", parts=self.slots_alive()), deadline=deadline)
        if found is None:  # cancelled, or handed back by a stopping worker
            return
        if found.state != "done":  # (the file cannot be read: the planner's error, as the whole plan gives it)
            self._end(slot, job_id, attempt, found)
            return
        wanted = [[int(x) for x in p] for p in found.values["pieces"]]  # (first, stop, chords, work)
        if sum(p[3] for p in wanted) < self.split_chords or len(wanted) < 2:
            slot.run(JOB, job_id, attempt, spec)
            return
        pieces = self.store.pieces(job_id, [(a, b, c) for a, b, c, _ in wanted])
        self.send(job_id, [p["first"] for p in pieces[1:] if p["state"] == "queued"])  # (the first: this worker's)
        outcome = self._plan_pieces(slot, job_id, attempt, spec, deadline)
        if outcome is None:  # cancelled (its pieces removed), or handed back (its pieces kept for the next start)
            if self.store.job_ended(job_id):
                self.store.drop_chunks(job_id)
            return
        if outcome.state == "done":
            note = split_note(self.store.chunks(job_id))
            planned = tuple(self.store.chunk_pieces(job_id))
            joined = slot.ask(job_id, attempt, replace(spec, pieces=planned), deadline=deadline)
            if joined is None:
                return
            outcome = replace(joined, values={**joined.values, "note": note})
        self._end(slot, job_id, attempt, outcome)

    def _plan_pieces(self, slot: Slot, job_id: str, attempt: int, spec: PlanSpec, deadline: float
                     ) -> Outcome | None:
        """Every piece planned (by any worker; those not taken by this one), or the first piece's failure: done or
        failed; None if the job was cancelled or handed back meanwhile."""
        shown = -1
        next_beat = 0.0
        slot.current = (job_id, attempt)
        try:
            while True:
                pieces = self.store.chunks(job_id)
                if not pieces:  # removed with the job's cancel
                    if self.store.state(JOB, job_id) != "running":
                        return None
                    return failed("internal", "the job's pieces were removed while it ran")
                bad = next((p for p in pieces if p["state"] == "failed"), None)
                if bad is not None:
                    return failed(bad["error_kind"] or "internal", bad["error"] or "a piece of the job failed")
                total = pieces[-1]["stop"] - pieces[0]["first"]
                planned = sum(p["stop"] - p["first"] for p in pieces if p["state"] == "done")
                if planned != shown:
                    shown = planned
                    with contextlib.suppress(Exception):
                        self.store.progress(JOB, job_id, attempt, Progress("plan", planned, total))
                if planned == total:
                    return Outcome("done")
                stale = now() - LEASE_S
                ready = [p for p in pieces if p["state"] == "queued"] + [
                    p for p in pieces if p["state"] == "running" and (p["heartbeat_at"] or 0.0) < stale]
                claimed = None
                for p in ready:
                    claimed = self.store.claim_chunk(job_id, p["first"], stale_before=stale)
                    if claimed is not None:
                        break
                if claimed is not None:
                    takes, piece = claimed
                    first = piece.piece[0] if piece.piece else 0
                    got = self._plan_piece(slot, job_id, first, takes, piece, deadline, attempt)
                    if got is None:
                        return None
                    self.store.finish_chunk(job_id, first, takes, got)
                    slot.current = (job_id, attempt)
                    continue
                # the other pieces are being planned elsewhere: hold the job meanwhile
                if self.stopping.is_set():
                    self.store.requeue(job_id, attempt)
                    return None
                if self.store.state(JOB, job_id) != "running":
                    return None
                if time.monotonic() > deadline:
                    return failed("limit", f"planning took longer than the service's limit of {self.job_timeout_s:g} s")
                if time.monotonic() >= next_beat:
                    next_beat = time.monotonic() + HEARTBEAT_EVERY
                    with contextlib.suppress(Exception):
                        self.store.heartbeat(JOB, job_id, attempt)
                self.stopping.wait(CANCEL_POLL)
        finally:
            slot.current = None

    def _plan_piece(self, slot: Slot, job_id: str, first: int, takes: int, piece: PlanSpec, deadline: float,
                    attempt: int | None = None) -> Outcome | None:
        """One piece planned in ``slot`` (its heartbeats; the job's too, from its coordinator: ``attempt``)."""
        def beat() -> None:
            self.store.chunk_beat(job_id, first, takes)
            if attempt is not None:
                self.store.heartbeat(JOB, job_id, attempt)

        def release() -> None:
            self.store.release_chunk(job_id, first, takes)
            if attempt is not None:
                self.store.requeue(job_id, attempt)

        live = (lambda state: state == "running") if attempt is not None else (lambda state: state in JOB.active)
        return slot.ask(job_id, attempt or 0, piece, beat=beat, live=live, on_stopping=release, progress=False,
                        deadline=deadline)

    def _end(self, slot: Slot, job_id: str, attempt: int, outcome: Outcome) -> None:
        """Store the job's end (its pieces dropped), then what its join left to make after it (a large job's 3D view
        data, as an unsplit job's: :meth:`.runner.Slot.run`)."""
        stored = False
        try:
            stored = slot._finish(JOB, job_id, attempt, outcome)
        finally:
            with contextlib.suppress(Exception):
                self.store.drop_chunks(job_id)
        if stored and outcome.later:
            slot._later(job_id)

    # -- any worker ---------------------------------------------------------------------------------------------------
    def run_piece(self, slot: Slot, job_id: str, first: int) -> str:
        """A piece's message: plan it if it is still queued and its job active ("ran"), else "skipped"."""
        claimed = self.store.claim_chunk(job_id, first)
        if claimed is None:
            return "skipped"
        takes, piece = claimed
        got = self._plan_piece(slot, job_id, first, takes, piece, time.monotonic() + self.job_timeout_s)
        if got is not None:
            self.store.finish_chunk(job_id, first, takes, got)
        return "ran"
