"""Benchmark: the REST service for path jobs (``planner.frontends.service``, issue 15) against planning called directly.

1. 500 jobs of 100 waypoints (smooth random 3-D curves, seeded) submitted as JSON by 20 concurrent clients to a
   real service (uvicorn on 127.0.0.1, ``--workers 2``, SQLite in WAL mode, development mode without keys):
   throughput (jobs/s from the first submit to the last job done), p50/p99 submit latency (the 202), p99
   completion time (created -> done, the service's clocks); none lost (every id answered, listed once, done),
   none duplicated (one start and one saved plan per job, in the store). Baseline in the same run: the same 500
   plans called directly (``plan`` + ``PlannedJob.save``, as a worker does) in a pool of the same number of processes.
   Targets on this 2-core machine: p99 submit latency below 50 ms, throughput at least 80 % of the baseline.
2. One whole NX job (``shared/data/nx_clsf_variable_contour_ust_a2.cls``, 12.9 million poses at 500 Hz) uploaded
   as a file: time to done, peak memory of the service (its process and its worker, VmHWM), storage per job, the
   time to first byte of the CSV and JSON exports and their streaming rate over the first 50 MB; baseline: ``planner
   plan`` on the same file (wall time and peak memory of the process).

3. The store's commits: 3000 single-job commits into SQLite, with SQLite's automatic WAL checkpoints inside the
   commits (its default) against the service's checkpoint thread (what a request waiting on a commit sees).

The machine's load average is printed with the figures: on a machine shared with other work the service gets only
its share of the cores, and the submit latency follows; the service's CPU per submit does not depend on the load.

Run: ``python bench/bench_service.py [--jobs 500] [--clients 20] [--workers 2]`` (a few minutes).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import http.client
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import httpx  # noqa: E402
from _common import print_table  # noqa: E402

NX_FILE = ROOT.parent / "shared" / "data" / "nx_clsf_variable_contour_ust_a2.cls"


def curves(n_jobs: int, n_points: int, seed: int = 15) -> list[list[list[float]]]:
    """Smooth 3-D curves in metres: sums of a few random sines, about 0.4 m long, no repeated points."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 1.0, n_points)
    out = []
    for _ in range(n_jobs):
        a, f, p = rng.uniform(0.01, 0.05, (3, 3)), rng.uniform(0.5, 2.0, (3, 3)), rng.uniform(0, 2 * np.pi, (3, 3))
        wobble = (a[None] * np.sin(2 * np.pi * f[None] * s[:, None, None] + p[None])).sum(axis=2)
        pts = np.c_[0.4 * s, np.zeros_like(s), np.zeros_like(s)] + wobble
        out.append(pts.round(9).tolist())
    return out


def _plan_and_save(points: list, folder: str, k: int) -> float:
    from planner import plan

    tic = time.perf_counter()
    plan(np.asarray(points), None).save(Path(folder) / f"{k}.job")
    return time.perf_counter() - tic


def _nice() -> None:
    from planner.frontends.service.tasks.child import WORKER_NICE

    os.nice(WORKER_NICE)


def direct(jobs: list, workers: int) -> float:
    """Wall time of the same plans (and saves) in a pool of ``workers`` processes, after warming it; the processes
    at the niceness of the service's workers (which matters on a machine shared with other work)."""
    with tempfile.TemporaryDirectory() as folder, cf.ProcessPoolExecutor(workers, initializer=_nice) as pool:
        list(pool.map(_plan_and_save, jobs[:workers], [folder] * workers, range(workers)))  # imports, first call
        tic = time.perf_counter()
        list(pool.map(_plan_and_save, jobs, [folder] * len(jobs), range(len(jobs)), chunksize=1))
        return time.perf_counter() - tic


class Service:
    """``python -m planner.frontends.service serve`` in development mode on a free loopback port."""

    def __init__(self, folder: Path, workers: int):
        env = {**os.environ, "PLANNER_DEV_NO_AUTH": "1", "PLANNER_DB": f"sqlite:///{folder / 'jobs.sqlite'}",
               "PLANNER_MAX_REQUEST_BYTES": str(64 << 20)}
        self.folder = folder
        self.proc = subprocess.Popen([sys.executable, "-m", "planner.frontends.service", "serve", "--port", "0",
                                      "--workers",
                                      str(workers)], cwd=folder, env=env, stdout=subprocess.PIPE)
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().decode()
        if "listening on " not in line:
            self.proc.kill()
            raise SystemExit(f"the service did not start: {line!r}")
        self.url = line.split("listening on ")[1].split()[0]
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(self.url + "/healthz").json()["workers"] == workers:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                self.proc.kill()
                raise SystemExit("the service is not healthy after 60 s")
            time.sleep(0.1)

    def peak_kib(self) -> dict[str, int]:
        """VmHWM (peak resident memory) of the service process and of each child, KiB."""
        pids = [self.proc.pid]
        for task in Path(f"/proc/{self.proc.pid}/task").iterdir():
            pids += [int(x) for x in (task / "children").read_text().split()]
        out = {}
        for pid in pids:
            status = Path(f"/proc/{pid}/status").read_text()
            comm = Path(f"/proc/{pid}/comm").read_text().strip()
            if pid != self.proc.pid and not comm.startswith("planner-"):  # multiprocessing's resource tracker
                continue
            name = "service" if pid == self.proc.pid else f"{comm} {pid}"
            out[name] = int(next(x for x in status.splitlines() if x.startswith("VmHWM")).split()[1])
        return out

    def loop_sched(self) -> tuple[float, float]:
        """The event loop's thread (the process's main thread): CPU time and time runnable but waiting for a core, s
        (/proc/PID/schedstat)."""
        run, wait, _ = map(int, Path(f"/proc/{self.proc.pid}/schedstat").read_text().split())
        return run / 1e9, wait / 1e9

    def cpu_s(self) -> float:
        """CPU time (user + system) the service process has used, s (its threads; not its worker processes)."""
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(30)


def run_clients(url: str, jobs: list, clients: int) -> tuple[list[float], list[str], float, list[float]]:
    """Submit every job from ``clients`` threads with the standard library's client (``--http-client threads``);
    (latencies s, ids, Unix time of the first submit, latencies of each client's first submit, which opens its
    connection, s). Its CPU per request (~0.2 ms, under one GIL) is about the service's own, on the same 2 cores:
    :func:`run_clients_async` is the default."""
    latencies: list[float] = []
    firsts: list[float] = []
    ids: list[str] = []
    lock = threading.Lock()
    start = threading.Barrier(clients)
    first = [float("inf")]

    host, port = url.split("//")[1].split(":")

    def client(k: int) -> None:  # the standard library's client: the clients' own CPU kept small
        mine = [json.dumps({"waypoints": pts}).encode() for pts in jobs[k::clients]]
        conn = http.client.HTTPConnection(host, int(port), timeout=60)
        start.wait()
        for j, body in enumerate(mine):
            wall, tic = time.time(), time.perf_counter()
            conn.request("POST", "/v1/jobs", body=body, headers={"Content-Type": "application/json"})
            r = conn.getresponse()
            answer = r.read()
            dt = time.perf_counter() - tic
            if r.status != 202:
                raise RuntimeError(f"submit answered {r.status}: {answer[:200]!r}")
            with lock:
                first[0] = min(first[0], wall)
                latencies.append(dt)
                if j == 0:
                    firsts.append(dt)
                ids.append(json.loads(answer)["id"])
        conn.close()

    threads = [threading.Thread(target=client, args=(k,)) for k in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return latencies, ids, first[0], firsts


def run_clients_async(url: str, jobs: list, clients: int,
                      start_at: float | None = None) -> tuple[list[float], list[str], float, list[float]]:
    """As :func:`run_clients`, the ``clients`` clients being connections of one asyncio (uvloop) event loop in this
    process, each sending its requests one after another (HTTP/1.1 keep-alive, each request's bytes prepared before
    the clock starts, the 202 read to its last byte before the clock stops, then checked). One thread: no GIL
    hand-overs between clients; ~0.05 ms of CPU per request, a quarter of the threads' (which took as much of the
    2 cores from the service as its own work). ``start_at``: the wall-clock time (``time.time()``) at which the
    clients start, every request prepared before it (clients in several processes start together, none while
    another process is still importing)."""
    import asyncio

    host, port = url.split("//")[1].split(":")
    latencies: list[float] = []
    firsts: list[float] = []
    answers: list[bytes] = []
    walls: list[float] = []

    def request(pts: list) -> bytes:
        body = json.dumps({"waypoints": pts}).encode()
        return (f"POST /v1/jobs HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Type: application/json\r\n"
                f"Content-Length: {len(body)}\r\n\r\n").encode() + body

    async def client(mine: list[bytes], start: asyncio.Event) -> None:
        writer = None
        await start.wait()
        for j, req in enumerate(mine):
            wall, tic = time.time(), time.perf_counter()
            if writer is None:  # (the first submit opens the connection: timed with it)
                reader, writer = await asyncio.open_connection(host, int(port))
            writer.write(req)
            head = await reader.readuntil(b"\r\n\r\n")
            length = int(head.lower().split(b"content-length:")[1].split(b"\r\n")[0])
            body = await reader.readexactly(length)
            dt = time.perf_counter() - tic
            if not head.startswith(b"HTTP/1.1 202"):
                raise RuntimeError(f"submit answered {head.splitlines()[0]!r}: {body[:200]!r}")
            latencies.append(dt)
            walls.append(wall)
            answers.append(body)
            if j == 0:
                firsts.append(dt)
        if writer is not None:
            writer.close()

    async def main() -> None:
        start = asyncio.Event()
        tasks = [asyncio.ensure_future(client([request(p) for p in jobs[k::clients]], start)) for k in range(clients)]
        await asyncio.sleep(0.05 if start_at is None else max(0.05, start_at - time.time()))  # all at the start line
        start.set()
        await asyncio.gather(*tasks)

    try:
        import uvloop

        uvloop.run(main())
    except ImportError:
        asyncio.run(main())
    return latencies, [json.loads(a)["id"] for a in answers], min(walls), firsts


def all_jobs(c: httpx.Client) -> list[dict]:
    out, cursor = [], None
    while True:
        page = c.get("/v1/jobs", params={"limit": 500, **({"cursor": cursor} if cursor else {})}).json()
        out += page["jobs"]
        cursor = page["next_cursor"]
        if cursor is None:
            return out


def bench_many(n_jobs: int, n_points: int, clients: int, workers: int, http_client: str = "asyncio") -> None:
    jobs = curves(n_jobs, n_points)
    t_direct = direct(jobs, workers)
    with tempfile.TemporaryDirectory() as tmp:
        svc = Service(Path(tmp), workers)
        try:
            cpu0, loop0, tic = svc.cpu_s(), svc.loop_sched(), time.perf_counter()
            run = run_clients_async if http_client == "asyncio" else run_clients
            lat, ids, t0, firsts = run(svc.url, jobs, clients)
            cpu_submit, wall_submit = svc.cpu_s() - cpu0, time.perf_counter() - tic
            loop_run, loop_wait = (b - a for a, b in zip(loop0, svc.loop_sched(), strict=True))
            with httpx.Client(base_url=svc.url, timeout=60) as c:
                while True:
                    counts = {}
                    for line in c.get("/metrics").text.splitlines():
                        if line.startswith("planner_jobs{"):
                            counts[line.split('"')[1]] = int(line.rsplit(" ", 1)[1])
                    if counts["queued"] + counts["running"] == 0:
                        break
                    time.sleep(0.5)  # (the end is the last job's finished_at, not when this poll sees it)
                listed = all_jobs(c)
                t_end = max(j["finished_at"] for j in listed)
            import sqlite3

            files: dict[str, list[str]] = {}  # the saved plans, in the store
            with sqlite3.connect(Path(tmp) / "jobs.sqlite") as db:
                for job_id, name in db.execute("select job_id, name from job_data where name = 'plan'"):
                    files.setdefault(job_id, []).append(name)
        finally:
            svc.stop()
    t_service = t_end - t0
    done = [j for j in listed if j["state"] == "done"]
    completion = [j["finished_at"] - j["created_at"] for j in done]
    lost = len(set(ids) - {j["id"] for j in listed}) + (n_jobs - len(set(ids)))
    duplicated = (len(listed) - len({j["id"] for j in listed}) + sum(j["attempts"] != 1 for j in listed)
                  + sum(len(v) != 1 for v in files.values()))
    lat_ms = np.array(lat) * 1e3
    what = "connections of one asyncio loop" if http_client == "asyncio" else "threads with http.client"
    print(f"\n{n_jobs} jobs x {n_points} waypoints, {clients} concurrent clients ({what}), {workers} worker "
          f"processes ({os.cpu_count()} cores)\n")
    print_table(
        ["", "jobs/s", "wall s", "ratio", "p50 submit ms", "p99 submit ms", "p99 completion s", "done", "lost",
         "duplicated"],
        [["direct: plan + save in a pool", f"{n_jobs / t_direct:.1f}", f"{t_direct:.2f}", "1.00", "", "", "",
          n_jobs, "", ""],
         ["service: POST /v1/jobs -> done", f"{n_jobs / t_service:.1f}", f"{t_service:.2f}",
          f"{t_direct / t_service:.2f}", f"{np.percentile(lat_ms, 50):.1f}", f"{np.percentile(lat_ms, 99):.1f}",
          f"{np.percentile(completion, 99):.2f}", len(done), lost, duplicated]])
    print(f"\ntargets: p99 submit latency < 50 ms ({'met' if np.percentile(lat_ms, 99) < 50 else 'NOT met'}), "
          f"throughput >= 80 % of direct ({'met' if t_direct / t_service >= 0.8 else 'NOT met'}); "
          f"none lost ({'yes' if lost == 0 and len(done) == n_jobs else 'NO'}), "
          f"none duplicated ({'yes' if duplicated == 0 else 'NO'}); "
          f"mean submit {statistics.fmean(lat_ms):.1f} ms")
    print(f"submit phase: {n_jobs} submits in {wall_submit:.2f} s; the service process used {cpu_submit:.2f} s of CPU "
          f"= {1e3 * cpu_submit / n_jobs:.2f} ms per submit (with its threads feeding the workers meanwhile), i.e. "
          f"{cpu_submit / wall_submit:.0%} of one core while {clients} clients waited on it; its event loop ran "
          f"{1e3 * loop_run:.0f} ms and waited {1e3 * loop_wait:.0f} ms for a core taken by other processes")
    rest = np.array(sorted(lat))
    for x in firsts:  # the other submits: on a connection already open
        rest = np.delete(rest, np.searchsorted(rest, x))
    print(f"first submit of each client (opens its connection; all {clients} at once): p50 "
          f"{1e3 * np.percentile(firsts, 50):.1f} ms, max {1e3 * max(firsts):.1f} ms; the other {rest.size} submits: "
          f"p50 {1e3 * np.percentile(rest, 50):.1f} ms, p99 {1e3 * np.percentile(rest, 99):.1f} ms")


def bench_commits(n: int = 3000) -> None:
    """One job row committed at a time into SQLite (WAL, synchronous=NORMAL): commit latency with SQLite's own
    checkpoints inside the commits (its default) against the service's checkpoints in a thread of their own."""
    import uuid

    from planner.frontends.service.inserter import JOBS
    from planner.frontends.service.store import Checkpointer, now, open_store

    body = json.dumps({"waypoints": curves(1, 100)[0]})
    rows = []
    for background in (False, True, False, True):
        with tempfile.TemporaryDirectory() as tmp:
            engine, sessions = open_store(f"sqlite:///{tmp}/jobs.sqlite", background_checkpoints=background)
            ckpt = Checkpointer(engine) if background else None
            if ckpt is not None:
                ckpt.start()
            times = []
            for _ in range(n):
                row = dict(id=uuid.uuid4().hex, owner="dev", state="queued", created_at=now(), stage="", done=0,
                           total=0, attempts=0, job_bytes=0, input_kind="waypoints", input_name="<waypoints>",
                           input_format="waypoints", input_bytes=len(body), input_json=body, settings="{}",
                           read_options="{}")
                tic = time.perf_counter()
                with sessions() as s:
                    s.connection().execute(JOBS.insert(), [row])
                    s.commit()
                times.append(time.perf_counter() - tic)
            if ckpt is not None:
                ckpt.stop()
            engine.dispose()
        t = np.array(times) * 1e3
        rows.append(["checkpoint thread (service)" if background else "in the commit (SQLite default)",
                     f"{np.percentile(t, 50):.2f}", f"{np.percentile(t, 99):.2f}", f"{np.percentile(t, 99.9):.2f}",
                     f"{t.max():.1f}", int((t > 20).sum())])
    print(f"\n{n} single-job commits into SQLite (WAL): where the WAL checkpoint (and its fsync) happens\n")
    print_table(["checkpoints", "p50 ms", "p99 ms", "p99.9 ms", "max ms", "commits > 20 ms"], rows)


def bench_nx(workers: int) -> None:
    if not NX_FILE.exists():
        print(f"\n{NX_FILE} not found: the whole-NX-job part is skipped")
        return
    tic = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "planner.frontends.cli", "plan", str(NX_FILE)],
                            stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    t_cli = time.perf_counter() - tic
    if status != 0:
        raise SystemExit("planner plan failed on the NX file")
    with tempfile.TemporaryDirectory() as tmp:
        svc = Service(Path(tmp), workers)
        try:
            with httpx.Client(base_url=svc.url, timeout=600) as c:
                tic = time.perf_counter()
                with open(NX_FILE, "rb") as f:
                    r = c.post("/v1/jobs", files={"file": (NX_FILE.name, f)})
                t_submit = time.perf_counter() - tic
                job_id = r.json()["id"]
                while (view := c.get(f"/v1/jobs/{job_id}").json())["state"] not in ("done", "failed"):
                    time.sleep(0.05)
                t_done = time.perf_counter() - tic
                if view["state"] != "done":
                    raise SystemExit(f"the NX job failed: {view['error']}")
                peaks = svc.peak_kib()
                streams = {}
                for fmt in ("csv", "json"):
                    tic = time.perf_counter()
                    with c.stream("GET", f"/v1/jobs/{job_id}/trajectory", params={"format": fmt}) as resp:
                        got, ttfb = 0, None
                        for piece in resp.iter_raw():
                            if ttfb is None:
                                ttfb = time.perf_counter() - tic
                            got += len(piece)
                            if got >= 50 << 20:
                                break
                    streams[fmt] = (ttfb, got / (time.perf_counter() - tic - ttfb) / 2**20)
        finally:
            svc.stop()
    poses = view["summary"]["duration_s"] * 500
    storage = view["storage_bytes"]
    print(f"\nwhole NX job: {NX_FILE.name} ({NX_FILE.stat().st_size / 2**20:.2f} MiB, "
          f"{view['summary']['passes']} passes, about {poses / 1e6:.1f} million poses at 500 Hz)\n")
    print_table(["", "time to done s", "peak memory MiB", "ratio"],
                [["planner plan (one process)", f"{t_cli:.2f}", f"{usage.ru_maxrss / 1024:.0f}", "1.00"],
                 [f"service (submit {t_submit:.2f} s incl. reading the file)", f"{t_done:.2f}",
                  f"{peaks['service'] / 1024:.0f} service, "
                  + ", ".join(f"{v / 1024:.0f} {k.split()[0]}" for k, v in peaks.items() if k != "service"),
                  f"{t_done / t_cli:.2f}"]])
    print(f"\nstorage per job: {storage / 2**20:.2f} MiB (input {view['input']['bytes'] / 2**20:.2f} MiB + saved "
          "plan + settings + summary); exports are streamed, never stored")
    print_table(["export", "time to first byte s", "rate MiB/s (first 50 MiB)"],
                [[fmt, f"{t:.2f}", f"{rate:.1f}"] for fmt, (t, rate) in streams.items()])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=500)
    ap.add_argument("--points", type=int, default=100)
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--http-client", choices=("asyncio", "threads"), default="asyncio",
                    help="the clients: connections of one asyncio loop (default) or threads with http.client")
    ap.add_argument("--skip-nx", action="store_true")
    args = ap.parse_args()
    print(f"load average at the start: {' '.join(f'{x:.1f}' for x in os.getloadavg())} ({os.cpu_count()} cores)")
    bench_many(args.jobs, args.points, args.clients, args.workers, args.http_client)
    print(f"load average: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    bench_commits()
    if not args.skip_nx:
        bench_nx(args.workers)


if __name__ == "__main__":
    main()
