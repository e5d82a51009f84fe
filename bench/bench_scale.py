"""Benchmark: the service's two task backends in the same run (issue 26) — local worker processes (the embedded
default: ``planner serve --workers W``, SQLite) against Celery (``planner worker --concurrency W`` on Redis, job
state and plans in PostgreSQL; Redis and PostgreSQL started by this script on loopback from Debian's packages).

1. Throughput and latency: N jobs of 100 waypoints (smooth random 3-D curves, seeded; the curves of
   bench_service.py) submitted as JSON by 20 concurrent clients, with 1, 2 and 4 worker processes: jobs/s from the
   first submit to the last job done, p50/p99 submit latency (the 202), p50/p99 completion latency (created -> done,
   the store's clocks), none lost (every job answered 202 done), duplicated (started or stored twice), or unfinished
   (still queued or running when the wait ends: slow, not lost). The celery rows also with two API replicas behind
   the clients (half of the clients on each, in a process of their own).
2. Per-task overhead of the broker: jobs of 3 waypoints submitted one at a time, each waited for: the median time
   from the job's row stored to its start in a worker (started_at - created_at) on each backend, and the median
   submit-to-done round trip.
3. The whole NX job split: its moves planned in pieces by 2 processes (sent back as bytes, as between machines) and
   joined, against one process; and through the celery backend (``planner worker`` x 2: the service
   plans its moves in pieces on both and joins them) against PLANNER_SPLIT_CHORDS=0, exports compared, the planning
   seconds of the coordinator and of the pieces; the same for its first passes (1/8, 1/4, 1/2 of its chords: from
   which size the split pays), and what a piece costs beyond its work (parse, chain, its moves' bytes, PostgreSQL).
4. The plan in the store: the whole NX job's saved plan (``shared/data/nx_clsf_variable_contour_ust_a2.cls``, the file
   of bench_cam.py) written to and read from the ``job_data`` table, SQLite and PostgreSQL: size and times.

Run: ``python bench/bench_scale.py [--jobs 1000] [--workers 1,2,4] [--quick] [--only replicas|nx-split]``
(``--quick``: 200 jobs, 1 and 2 workers, no NX plan; a few minutes; ``--only replicas``: the row "celery, 2 API
replicas" alone; ``--only nx-split``: the NX job through the service alone). Both backends run on this machine's
cores: a ratio near 1 says the broker costs little per task; more workers than cores add nothing here.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import httpx  # noqa: E402
from _common import print_table  # noqa: E402
from bench_service import all_jobs, curves, run_clients_async  # noqa: E402

NX_FILE = ROOT.parent / "shared" / "data" / "nx_clsf_variable_contour_ust_a2.cls"
CLIENTS = 20


class Proc:
    """A ``planner serve`` or ``planner worker`` subprocess."""

    def __init__(self, args: list[str], env: dict, folder: Path, name: str):
        self.log = open(folder / f"{name}.log", "ab")  # noqa: SIM115
        self.proc = subprocess.Popen([sys.executable, "-m", "planner.frontends.service", *args], cwd=folder, env=env,
                                     stdout=subprocess.PIPE if args[0] == "serve" else self.log, stderr=self.log)
        self.url = ""
        if args[0] == "serve":
            assert self.proc.stdout is not None
            line = self.proc.stdout.readline().decode()
            if "listening on " not in line:
                raise SystemExit(f"the service did not start: {line!r}")
            self.url = line.split("listening on ")[1].split()[0]

    def wait_workers(self, n: int, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                if httpx.get(self.url + "/healthz", timeout=5).json()["workers"] == n:
                    return
            except (httpx.TransportError, KeyError, ValueError):
                pass
            if time.monotonic() > deadline:
                raise SystemExit(f"{n} workers not alive after {timeout} s")
            time.sleep(0.1)

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)
        self.log.close()


def cluster(backend: str, workers: int, folder: Path, pg, redis,
            replicas: int = 1, extra: dict | None = None) -> tuple[list[Proc], list[Proc], str]:
    """API replicas and workers of ``backend`` (``extra``: more of their environment), healthy, and their
    database's URL."""
    env = {**{k: v for k, v in os.environ.items() if not k.startswith("PLANNER_")}, "PLANNER_DEV_NO_AUTH": "1",
           "PLANNER_MAX_REQUEST_BYTES": str(64 << 20), **(extra or {})}
    if backend == "local":
        env["PLANNER_DB"] = f"sqlite:///{folder / 'jobs.sqlite'}"
        api = Proc(["serve", "--port", "0", "--workers", str(workers)], env, folder, "api")
        api.wait_workers(workers)
        return [api], [], env["PLANNER_DB"]
    from planner.frontends.service.store import open_store

    db = pg.create_database()
    open_store(db)[0].dispose()  # migrated once, before the processes start
    env.update(PLANNER_QUEUE="celery", PLANNER_BROKER=redis.url.rsplit("/", 1)[0] + f"/{1 + hash(folder) % 15}",
               PLANNER_DB=db, PLANNER_DATA=str(folder / "data"))
    subprocess.run(["redis-cli", "-u", env["PLANNER_BROKER"], "FLUSHDB"], capture_output=True, check=False)
    pool = [Proc(["worker", "--concurrency", "1"], env, folder, f"worker{i}") for i in range(workers)] if (
        extra or {}).get("PLANNER_SPLIT_CHORDS") is not None else [
        Proc(["worker", "--concurrency", str(workers)], env, folder, "worker")]
    apis = [Proc(["serve", "--port", "0"], env, folder, f"api{i}") for i in range(replicas)]
    for a in apis:
        a.wait_workers(workers)
    return apis, pool, db


def throughput(backend: str, workers: int, jobs: list, pg, redis, replicas: int = 1, wait_s: float = 900.0) -> dict:
    """``jobs`` submitted by :data:`CLIENTS` clients (split evenly between the replicas; with two replicas each half
    of the clients runs in a process of its own, as clients on other machines do: two event loops in one process
    took turns at its GIL and timed each other's turns) and waited for (at most ``wait_s`` s after the last submit).

    Counted from the store's own list: ``lost`` a job answered 202 that is not listed or ended failed or cancelled;
    ``unfinished`` a job still queued or running when the wait ended (neither lost nor duplicated: slow);
    ``duplicated`` a done job that was started more than once or whose plan was stored more than once, or an id
    listed twice."""
    with tempfile.TemporaryDirectory() as tmp:
        apis, pool, db = cluster(backend, workers, Path(tmp), pg, redis, replicas)
        try:
            share = [jobs[i::len(apis)] for i in range(len(apis))]
            import concurrent.futures as cf
            import multiprocessing

            with cf.ProcessPoolExecutor(len(apis), mp_context=multiprocessing.get_context("spawn")) as ex:
                start_at = [time.time() + 3.0] * len(apis)  # both processes started and ready (spawn: ~1 s each)
                runs = list(ex.map(run_clients_async, [a.url for a in apis], share, [CLIENTS // len(apis)] * len(apis),
                                   start_at))
            lat = [x for r in runs for x in r[0]]
            ids = [x for r in runs for x in r[1]]
            t0 = min(r[2] for r in runs)
            with httpx.Client(base_url=apis[0].url, timeout=60) as c:
                deadline = time.monotonic() + wait_s
                while True:
                    counts = {line.split('"')[1]: int(line.rsplit(" ", 1)[1]) for line in c.get("/metrics").text
                              .splitlines() if line.startswith("planner_jobs{")}
                    if counts["queued"] + counts["running"] == 0 or time.monotonic() > deadline:
                        break
                    time.sleep(0.25)
                listed = all_jobs(c)
                plans = plan_rows(db)
        finally:
            for p in apis + pool:
                p.stop()
    done = [j for j in listed if j["state"] == "done"]
    unfinished = sum(j["state"] in ("queued", "running") for j in listed)
    by_id = {j["id"] for j in listed}
    lost = len(set(ids) - by_id) + sum(j["state"] in ("failed", "cancelled") for j in listed)
    duplicated = (sum(j["attempts"] > 1 for j in done) + (len(listed) - len(by_id)) + max(0, plans["rows"] - len(done))
                  + plans["repeated"])
    lat_ms = np.array(lat) * 1e3
    t_end = max((j["finished_at"] for j in done), default=t0 + 1.0)
    completion = np.array([j["finished_at"] - j["created_at"] for j in done] or [np.nan])
    return {"rate": len(done) / (t_end - t0), "p50s": np.percentile(lat_ms, 50), "p99s": np.percentile(lat_ms, 99),
            "p50c": np.percentile(completion, 50), "p99c": np.percentile(completion, 99), "lost": lost,
            "dup": duplicated, "unfinished": unfinished}


def plan_rows(db: str) -> dict:
    """Stored plans: rows, and plans of a job stored more than once (a job's plan is one row, named 'plan')."""
    from sqlalchemy import create_engine, text

    engine = create_engine(db)
    try:
        with engine.connect() as conn:
            rows = int(conn.scalar(text("select count(*) from job_data where name = 'plan'")))
            repeated = int(conn.scalar(text("select count(*) - count(distinct job_id) from job_data "
                                            "where name = 'plan'")))
            return {"rows": rows, "repeated": repeated}
    finally:
        engine.dispose()


def overhead(backend: str, pg, redis, n: int = 40) -> tuple[float, float]:
    """Median (row stored -> started in a worker, submit -> done seen) of tiny jobs one at a time, ms."""
    with tempfile.TemporaryDirectory() as tmp:
        apis, pool, _ = cluster(backend, 1, Path(tmp), pg, redis)
        try:
            waits, trips = [], []
            with httpx.Client(base_url=apis[0].url, timeout=60) as c:
                for i in range(n):
                    tic = time.perf_counter()
                    job_id = c.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.01 * i, 0], [0.2, 0, 0]]}
                                    ).json()["id"]
                    while (v := c.get(f"/v1/jobs/{job_id}").json())["state"] not in ("done", "failed"):
                        time.sleep(0.002)
                    trips.append(time.perf_counter() - tic)
                    waits.append(v["started_at"] - v["created_at"])
        finally:
            for p in apis + pool:
                p.stop()
    return 1e3 * float(np.median(waits[5:])), 1e3 * float(np.median(trips[5:]))


def _plan_piece(start: int, stop: int) -> tuple[bytes, float]:
    import importlib

    from planner.job import piece_to_bytes

    tic = time.perf_counter()
    piece = importlib.import_module("planner.plan").plan_piece(NX_FILE, None, start, stop)
    return piece_to_bytes(piece), time.perf_counter() - tic


def nx_split(workers: int = 2) -> tuple[list[list[str]], bytes]:
    """The whole NX job planned in one process against its moves planned in pieces by ``workers`` processes
    (:func:`planner.plan.plan_pieces`, :func:`planner.plan.plan_piece`; each piece sent back as bytes, as between
    machines) and joined (``plan(pieces=...)``): the service's split without the service; rows for the table, and the
    plan."""
    import concurrent.futures as cf
    import importlib

    from planner import plan
    from planner.job import piece_from_bytes

    P = importlib.import_module("planner.plan")
    tic = time.perf_counter()
    whole = plan(NX_FILE)
    t_one = time.perf_counter() - tic
    tic = time.perf_counter()
    pieces = [(a, b) for a, b, _, _ in P.plan_pieces(NX_FILE, None, workers)]
    t_find = time.perf_counter() - tic
    with cf.ProcessPoolExecutor(workers) as pool:
        list(pool.map(abs, range(workers)))  # the processes started (as warm workers are)
        tic = time.perf_counter()
        got = list(pool.map(_plan_piece, *zip(*pieces, strict=True)))
        t_pieces = time.perf_counter() - tic
    tic = time.perf_counter()
    joined = plan(NX_FILE, pieces=[piece_from_bytes(data) for data, _ in got])
    t_join = time.perf_counter() - tic
    from planner.export import stream

    if b"".join(stream(joined, "csv")) != b"".join(stream(whole, "csv")):
        raise SystemExit("the joined NX job's CSV differs from the one process's (tests/test_plan_split.py)")
    sent = sum(len(d) for d, _ in got)
    total = t_find + t_pieces + t_join
    rows = [["one process", f"{t_one:.1f}", "", "", "", "", "1.00"],
            [f"{len(pieces)} pieces on {workers} processes, joined", f"{total:.1f}", f"{t_find:.1f}",
             f"{t_pieces:.1f} ({', '.join(f'{t:.1f}' for _, t in got)})", f"{t_join:.1f}", f"{sent / 2**20:.1f}",
             f"{t_one / total:.2f}"]]
    return rows, whole.to_bytes()


#: Parts of the NX job through the service (its first passes, by CAM chords), and the whole: where the split starts to
#: pay.
NX_PARTS = (0.125, 0.25, 0.5, 1.0)


def _nx_passes(fraction: float) -> list[int] | None:
    """The NX job's first passes holding ``fraction`` of its CAM chords (None: all)."""
    if fraction >= 1.0:
        return None
    import importlib

    P = importlib.import_module("planner.plan")
    chords = np.cumsum([c for _, _, c, _ in P.plan_pieces(NX_FILE, None, 10**6)])
    return list(range(int(np.searchsorted(chords, fraction * chords[-1])) + 1))


def nx_service_split(pg, redis, workers: int = 2) -> tuple[list[list[str]], list[list[str]]]:
    """The NX job (its first passes, :data:`NX_PARTS`, and the whole) through the celery backend with ``workers``
    worker processes (one ``planner worker`` each): split across them (PLANNER_SPLIT_CHORDS=1000: every part) against
    planned in one process (PLANNER_SPLIT_CHORDS=0): submit to done (the store's clocks), the planning seconds of the
    coordinator (the join) and of the pieces (the job's note), the two plans' CSV and JSON exports compared byte for
    byte. Rows for the table of the whole job, and for the table by size."""
    import hashlib

    parts = [(f, _nx_passes(f)) for f in NX_PARTS]
    runs: dict[str, list[dict]] = {}
    for label, chords in (("split", "1000"), ("one", "0")):
        runs[label] = []
        with tempfile.TemporaryDirectory() as tmp:
            apis, pool, _ = cluster("celery", workers, Path(tmp), pg, redis, extra={"PLANNER_SPLIT_CHORDS": chords})
            try:
                with httpx.Client(base_url=apis[0].url, timeout=120) as c:
                    for i in range(2 * workers):  # every worker's process started (as warm workers are)
                        c.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.01 * i, 0], [0.2, 0, 0]]})
                    while c.get("/metrics").text.count('planner_jobs{state="done"} ' + str(2 * workers)) == 0:
                        time.sleep(0.2)
                    for _, passes in parts:
                        with open(NX_FILE, "rb") as f:
                            settings = {} if passes is None else {"passes": passes}
                            job_id = c.post("/v1/jobs", files={"file": (NX_FILE.name, f)},
                                            data={"settings": json.dumps(settings)}).json()["id"]
                        while (v := c.get(f"/v1/jobs/{job_id}").json())["state"] not in ("done", "failed"):
                            time.sleep(0.1)
                        if v["state"] != "done":
                            raise SystemExit(f"the NX job failed: {v['error']}")
                        digest = []
                        for fmt in ("csv", "json"):
                            h = hashlib.sha256()
                            with c.stream("GET", f"/v1/jobs/{job_id}/trajectory?format={fmt}") as r:
                                for piece in r.iter_bytes():
                                    h.update(piece)
                            digest.append(h.hexdigest())
                        runs[label].append({"s": v["finished_at"] - v["created_at"], "digest": digest,
                                            "join": v["timings"]["planning_s"], "note": v["note"] or "",
                                            "passes": v["summary"]["passes"]})
            finally:
                for p in apis + pool:
                    p.stop()
    split, one = runs["split"][-1], runs["one"][-1]
    rows = [[f"split across {workers} workers", f"{split['s']:.1f}", f"{one['s'] / split['s']:.2f}",
             f"{split['join']:.1f}", _piece_seconds(split["note"]), split["note"]],
            ["one process", f"{one['s']:.1f}", "1.00", f"{one['join']:.1f}", "", ""],
            ["exports (CSV, JSON) of the two byte for byte the same", "", "", "", "",
             str(split["digest"] == one["digest"])]]
    by_size = [[f"{f:g}", str(sp["passes"]), f"{sp['s']:.1f}", f"{on['s']:.1f}", f"{on['s'] / sp['s']:.2f}",
                _piece_seconds(sp["note"]), str(sp["digest"] == on["digest"])]
               for (f, _), sp, on in zip(parts, runs["split"], runs["one"], strict=True)]
    return rows, by_size


def _piece_seconds(note: str) -> str:
    """The pieces' planning seconds from a split job's note ("...; piece s 5.1, 4.9)")."""
    return note.split("piece s ")[1].split(")")[0] if "piece s " in note else ""


def split_overhead(pg) -> list[list[str]]:
    """What a piece of the NX job split in two costs beyond its work, in this process: the file's parse and split
    into moves (each piece, the pieces step and the join pay it), the chain of the moves before it, its moves to
    bytes and back, their write to and read from PostgreSQL's job_data, and the join. Rows for the table."""
    import importlib

    from sqlalchemy import delete, insert, select

    from planner import plan
    from planner.frontends.service.store import JobData, now, open_store
    from planner.job import piece_from_bytes, piece_to_bytes

    P = importlib.import_module("planner.plan")
    tic = time.perf_counter()
    P.fit_batches(NX_FILE)  # a parse and split into moves, nothing else
    t_parse = time.perf_counter() - tic
    engine, _ = open_store(pg.create_database())
    rows, pieces = [], []
    try:
        for k, (a, b, chords, _) in enumerate(P.plan_pieces(NX_FILE, None, 2)):
            piece = P.plan_piece(NX_FILE, None, a, b)
            tic = time.perf_counter()
            data = piece_to_bytes(piece)
            t_enc = time.perf_counter() - tic
            tic = time.perf_counter()
            with engine.begin() as conn:
                conn.execute(delete(JobData).where(JobData.job_id == "nx"))
                conn.execute(insert(JobData).values(job_id="nx", name=f"piece.{a}", data=data, bytes=len(data),
                                                    created_at=now()))
            with engine.connect() as conn:
                data = bytes(conn.scalar(select(JobData.data).where(JobData.job_id == "nx")))
            t_db = time.perf_counter() - tic
            tic = time.perf_counter()
            pieces.append(piece_from_bytes(data))
            t_dec = time.perf_counter() - tic
            t = piece.timings
            rows.append([f"piece {k + 1}: passes {a}..{b - 1}, {chords} chords", f"{t['piece']:.2f}",
                         f"{t_parse:.2f}", f"{t['chain']:.2f}", f"{len(data) / 2**20:.1f}", f"{t_enc + t_dec:.2f}",
                         f"{t_db:.2f}"])
    finally:
        engine.dispose()
    tic = time.perf_counter()
    plan(NX_FILE, pieces=pieces)
    rows.append(["the join (parse, checks, whole-sequence steps)", f"{time.perf_counter() - tic:.2f}", f"{t_parse:.2f}",
                 "", "", "", ""])
    return rows


def print_nx_service_split(pg, redis) -> None:
    from planner.frontends.service.config import SPLIT_CHORDS

    rows, by_size = nx_service_split(pg, redis)
    print_table(["", "submit to done s", "x one", "planning s: coordinator (join)", "pieces", "note"], rows)
    print("\nby size (the NX job's first passes, by fraction of its CAM chords; split: PLANNER_SPLIT_CHORDS=1000)")
    print_table(["fraction", "passes", "split s", "one s", "x one", "pieces s", "exports the same"], by_size)
    print(f"\nwhat a piece costs beyond its work (the NX job in 2 pieces, in this process; the default "
          f"PLANNER_SPLIT_CHORDS: {SPLIT_CHORDS})")
    print_table(["", "piece s", "parse + split s", "chain s", "moves MiB", "to bytes + back s", "PostgreSQL w+r s"],
                split_overhead(pg))


def plan_storage(pg, blob: bytes) -> list[list[str]]:
    """The whole NX job's saved plan written to and read from job_data (SQLite, PostgreSQL): rows for the table."""
    from sqlalchemy import delete, insert, select

    from planner.frontends.service.store import JobData, now, open_store

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, url in (("SQLite (WAL)", f"sqlite:///{tmp}/j.sqlite"), ("PostgreSQL", pg.create_database())):
            engine, _ = open_store(url)
            w, r = [], []
            for _ in range(5):
                tic = time.perf_counter()
                with engine.begin() as conn:
                    conn.execute(delete(JobData).where(JobData.job_id == "nx"))
                    conn.execute(insert(JobData).values(job_id="nx", name="plan", data=blob, bytes=len(blob),
                                                        created_at=now()))
                w.append(time.perf_counter() - tic)
                tic = time.perf_counter()
                with engine.connect() as conn:
                    got = conn.scalar(select(JobData.data).where(JobData.job_id == "nx"))
                r.append(time.perf_counter() - tic)
                assert bytes(got) == blob
            engine.dispose()
            rows.append([name, f"{len(blob) / 2**20:.2f}", f"{1e3 * min(w):.1f}", f"{1e3 * min(r):.1f}"])
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1000)
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--quick", action="store_true", help="200 jobs, 1 and 2 workers, no NX plan")
    ap.add_argument("--only", choices=["replicas", "nx-split"],
                    help="only the row 'celery, 2 API replicas' (2 workers), or only the NX job split through the "
                         "service")
    args = ap.parse_args()
    n_jobs, counts = (200, [1, 2]) if args.quick else (args.jobs, [int(x) for x in args.workers.split(",")])
    import signal

    from tests.pg_server import PostgresServer
    from tests.redis_server import RedisServer

    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # the servers stopped on a kill too
    pg, redis = PostgresServer().start(), RedisServer(appendonly=False).start()
    try:
        if args.only == "nx-split":
            print(f"the whole NX job ({NX_FILE.name}) through the celery backend, 2 worker processes, load average "
                  f"{os.getloadavg()[0]:.1f}")
            print_nx_service_split(pg, redis)
            print(f"load average after: {os.getloadavg()[0]:.1f}")
            return
        if args.only == "replicas":
            jobs = curves(n_jobs, 100)
            print(f"{n_jobs} jobs x 100 waypoints, {CLIENTS} clients, 2 API replicas, 2 workers, load average "
                  f"{os.getloadavg()[0]:.1f}")
            r = throughput("celery", 2, jobs, pg, redis, 2)
            print_table(["backend", "workers", "jobs/s", "p50 submit ms", "p99 submit ms", "p50 completion s",
                         "p99 completion s", "lost", "duplicated", "unfinished"],
                        [["celery, 2 API replicas", 2, f"{r['rate']:.1f}", f"{r['p50s']:.1f}", f"{r['p99s']:.1f}",
                          f"{r['p50c']:.2f}", f"{r['p99c']:.2f}", r["lost"], r["dup"], r["unfinished"]]])
            print(f"load average after: {os.getloadavg()[0]:.1f}")
            return
        jobs = curves(n_jobs, 100)
        print(f"{n_jobs} jobs x 100 waypoints, {CLIENTS} concurrent clients, {os.cpu_count()} cores, load average "
              f"{os.getloadavg()[0]:.1f}\n")
        rows, rate = [], {}
        for w in counts:
            for backend, replicas in (("local", 1), ("celery", 1), ("celery", 2)):
                if replicas == 2 and w != 2:
                    continue
                r = throughput(backend, w, jobs, pg, redis, replicas)
                rate[(backend, w, replicas)] = r["rate"]
                ratio = r["rate"] / rate[("local", w, 1)]
                rows.append([f"{backend}{'' if replicas == 1 else ', 2 API replicas'}", w, f"{r['rate']:.1f}",
                             f"{ratio:.2f}", f"{r['p50s']:.1f}", f"{r['p99s']:.1f}", f"{r['p50c']:.2f}",
                             f"{r['p99c']:.2f}", r["lost"], r["dup"], r["unfinished"]])
                print_table(["backend", "workers", "jobs/s", "x local", "p50 submit ms", "p99 submit ms",
                             "p50 completion s", "p99 completion s", "lost", "duplicated", "unfinished"], rows[-1:])
        print()
        print_table(["backend", "workers", "jobs/s", "x local", "p50 submit ms", "p99 submit ms", "p50 completion s",
                     "p99 completion s", "lost", "duplicated", "unfinished"], rows)
        if ("celery", 2, 1) in rate:
            print(f"\ntarget: celery with 2 workers >= 0.9 x local with 2 processes: "
                  f"{rate[('celery', 2, 1)] / rate[('local', 2, 1)]:.2f}")
        print("\nper-task overhead (tiny jobs one at a time, medians):")
        ov = {b: overhead(b, pg, redis) for b in ("local", "celery")}
        print_table(["backend", "stored -> started ms", "submit -> done seen ms"],
                    [[b, f"{a:.1f}", f"{t:.1f}"] for b, (a, t) in ov.items()])
        if not args.quick and NX_FILE.exists():
            rows, blob = nx_split()
            print(f"\nthe whole NX job ({NX_FILE.name}) split: its moves planned in pieces on other processes and "
                  "joined (the exports byte for byte the same: tests/test_plan_split.py)")
            print_table(["", "wall s", "pieces found s", "pieces planned s", "join s", "pieces sent MiB", "x one"],
                        rows)
            print("\nthe same through the celery backend (2 worker processes): split across them against one process")
            print_nx_service_split(pg, redis)
            print(f"\nthe whole NX job's plan in the store ({NX_FILE.name}):")
            print_table(["database", "plan MiB", "write ms", "read ms"], plan_storage(pg, blob))
    finally:
        redis.stop()
        pg.stop()


if __name__ == "__main__":
    main()
