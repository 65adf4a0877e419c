"""Benchmark: the local pool against a 2-worker Dask cluster, and what Dask costs per chunk.

For the baseline and one planner, the same small campaign runs alternately on the local
pebble pool (``--workers 2``) and on a Dask ``LocalCluster`` of two worker processes
(``--cluster local --workers 2``), ``--repeats`` times each, into fresh directories; it
reports trials per wall second of each and Dask's overhead as the ratio of the medians
(runs interleaved, so load on this shared machine falls on both alike). Campaign wall time
includes starting the pool or cluster, as a user pays it.

Then, on one 2-worker cluster, the quantities a projection to many workers needs:

* the scheduler's throughput for tiny tasks (tasks per second, 2,000 no-op tasks);
* the bytes a trial's result carries back (a chunk's pickled result / its trials);
* the campaign process's write rate (rows per second into the durable store, one fsync
  per row): the single writer every result passes through.

and projects trials per second for 10 to 1,000 workers: each worker flies one trial at a
time, so the cluster asks for ``workers / mean trial time`` trials per second; the
scheduler can hand out ``tasks/s x chunk size``, the writer can take its rate. Timings
are never asserted.

    .venv/bin/python bench/bench_executors.py                  # ~5 min on 2 cores
    .venv/bin/python bench/bench_executors.py --json
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (its BLAS settings before numpy loads)
# isort: on

import argparse  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import textwrap  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from benchutil import machine_info  # noqa: E402

from ft_sitl.missions.campaign import _chunks, run_campaign, run_chunk  # noqa: E402
from ft_sitl.missions.campaign_file import load_campaign  # noqa: E402
from ft_sitl.missions.executors import DaskExecutor, LocalExecutor  # noqa: E402
from ft_sitl.missions.store import ResultStore, load_rows  # noqa: E402

CAMPAIGNS = {
    # the baseline: short trials, so per-trial and per-chunk overheads show (two
    # configurations, 24 trials each: a configuration's trials share its scene, as the
    # paper matrix's 180 do)
    "straight": """\
        name = "bench-straight"
        algorithms = ["straight"]
        platforms = "all"
        scenarios = [{family = "forest", indices = [1, 2]}]
        trials = 2
        """,
    # a planner: trials of seconds, as most of the paper matrix
    "fast": """\
        name = "bench-fast"
        algorithms = ["fast"]
        platforms = ["0.98kg-EGO Planner DIY", "1.00kg-SunnySky", "2.00kg-UAV 8",
                     "2.00kg-T-MOTOR", "4.50kg-T-MOTOR", "1.50kg-DJI"]
        scenarios = [{family = "forest", indices = [1]}]
        trials = 1
        """,
}


def one_run(campaign, kind: str, workers: int, chunk: int) -> dict:
    with tempfile.TemporaryDirectory() as d:
        ex = (LocalExecutor(workers, Path(d) / ".grids") if kind == "local" else
              DaskExecutor(local_workers=workers, chunk_max=chunk))
        t0 = time.perf_counter()
        s = run_campaign(campaign, Path(d) / "out", executor=ex, progress=False)
        wall = time.perf_counter() - t0
        _, rows = load_rows(Path(d) / "out")
    return {"kind": kind, "trials": s.ran, "errors": len(s.errors), "wall_s": wall,
            "trials_per_s": s.ran / wall,
            "sum_trial_wall_s": sum(r["wall_time_s"] for r in rows)}


def _noop(x):
    return x


def scheduler_rate(client, n: int = 2000) -> float:
    t0 = time.perf_counter()
    futs = client.map(_noop, range(n), pure=False)
    client.gather(futs)
    return n / (time.perf_counter() - t0)


def result_bytes(campaign, chunk: int) -> float:
    """Pickled bytes per trial of a chunk's result (as it travels back)."""
    c = _chunks(campaign.trial_specs(), chunk)[0]
    res = run_chunk(c)
    return len(pickle.dumps(("tcp://127.0.0.1:1", res))) / len(c)


def writer_rate(rows: list[dict], n: int = 400) -> float:
    """Rows per second the result store appends durably (one fsync per row)."""
    with tempfile.TemporaryDirectory() as d:
        store = ResultStore(d)
        store.open({"spec": {"name": "bench"}})
        t0 = time.perf_counter()
        for k in range(n):
            row = dict(rows[k % len(rows)], trial_id=f"{k:016x}")
            store.append(row)
        dt = time.perf_counter() - t0
        store.close()
    return n / dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=10, help="trials per Dask task")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    out = {"machine": machine_info(None), "chunk": args.chunk, "algorithms": {}}
    with tempfile.TemporaryDirectory() as root:
        campaigns = {}
        for name, text in CAMPAIGNS.items():
            p = Path(root) / f"{name}.toml"
            p.write_text(textwrap.dedent(text))
            campaigns[name] = load_campaign(p)
        for name, c in campaigns.items():
            runs = {"local": [], "dask": []}
            for _ in range(args.repeats):
                for kind in ("local", "dask"):
                    r = one_run(c, kind, 2, args.chunk)
                    runs[kind].append(r)
                    print(f"{name:9s} {kind:5s} {r['trials']:4d} trials {r['wall_s']:7.1f} s "
                          f"{r['trials_per_s']:.3f} trials/s", file=sys.stderr)
            loc = statistics.median(r["trials_per_s"] for r in runs["local"])
            dsk = statistics.median(r["trials_per_s"] for r in runs["dask"])
            mean_trial = statistics.mean(r["sum_trial_wall_s"] / r["trials"]
                                         for r in runs["local"])
            out["algorithms"][name] = {
                "runs": runs, "local_trials_per_s": loc, "dask_trials_per_s": dsk,
                "dask_overhead": loc / dsk - 1.0, "mean_trial_wall_s": mean_trial}

        ex = DaskExecutor(local_workers=2, chunk_max=args.chunk)
        ex.start()
        try:
            out["scheduler_tasks_per_s"] = scheduler_rate(ex.client)
        finally:
            ex.close()
        out["result_bytes_per_trial"] = result_bytes(campaigns["straight"], args.chunk)
        with tempfile.TemporaryDirectory() as d:
            run_campaign(campaigns["straight"], d, progress=False, limit=4)
            _, rows = load_rows(d)
        out["writer_rows_per_s"] = writer_rate(rows)

    proj = []
    sched = out["scheduler_tasks_per_s"] * args.chunk
    for name, a in out["algorithms"].items():
        for w in (10, 100, 1000):
            demand = w / a["mean_trial_wall_s"]
            proj.append({"algorithm": name, "workers": w, "demand_trials_per_s": demand,
                         "scheduler_limit_trials_per_s": sched,
                         "writer_limit_trials_per_s": out["writer_rows_per_s"],
                         "projected_trials_per_s": min(demand, sched,
                                                       out["writer_rows_per_s"]),
                         "result_mb_per_s": min(demand, sched) *
                         out["result_bytes_per_trial"] / 1e6})
    out["projection"] = proj
    if args.json:
        print(json.dumps(out, indent=2, default=float))
        return 0
    print(f"machine: {out['machine']}")
    for name, a in out["algorithms"].items():
        print(f"{name}: local {a['local_trials_per_s']:.3f} trials/s, Dask "
              f"{a['dask_trials_per_s']:.3f} trials/s, Dask overhead "
              f"{100 * a['dask_overhead']:+.1f} %  (mean trial {a['mean_trial_wall_s']:.2f} s)")
    print(f"scheduler: {out['scheduler_tasks_per_s']:.0f} tiny tasks/s; result "
          f"{out['result_bytes_per_trial']:.0f} B/trial; writer "
          f"{out['writer_rows_per_s']:.0f} rows/s")
    for p in proj:
        print(f"  {p['algorithm']:9s} {p['workers']:5d} workers: demand "
              f"{p['demand_trials_per_s']:8.1f}/s, projected {p['projected_trials_per_s']:8.1f}"
              f"/s, results {p['result_mb_per_s']:.2f} MB/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
