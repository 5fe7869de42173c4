"""Diagnose a fleet of valves on a Dask cluster through the valve_bridge package.

Each recording of a directory listing (``valve_bridge.fleet_jobs``: one valve per file, or per
tag of a column-mapping file) is one Dask task running ``valve_bridge.diagnose_valve``, the same
library call ``valve-bridge fleet`` makes; the rows are gathered and ranked by
``valve_bridge.fleet_report`` into the same summary (index.html, summary.csv, summary.json).
Dask schedules; nothing here does.

    python3 python/examples/dask_fleet.py DIR OUT [SCHEDULER_ADDRESS]

Without an address it starts a LocalCluster of 2 worker processes on this machine; with one
(``tcp://scheduler:8786``) it uses that cluster, whose workers must see DIR and OUT at the same
paths (a shared file system).
"""

import sys
import time

from dask.distributed import Client, LocalCluster

import valve_bridge as vb


def diagnose_fleet(client, directory, out=None, valves=None):
    """Maps diagnosis over the valves of ``directory`` on ``client`` and returns the ranked
    fleet summary (the document of ``summary.json``)."""
    jobs = vb.fleet_jobs(str(directory), None if valves is None else str(valves))
    futures = client.map(
        vb.diagnose_valve, jobs, out=None if out is None else str(out), pure=False
    )
    rows = client.gather(futures)
    return vb.fleet_report(rows, None if out is None else str(out))


def main(argv):
    directory, out = argv[1], argv[2]
    if len(argv) > 3:
        client = Client(argv[3])
    else:
        client = Client(LocalCluster(n_workers=2, threads_per_worker=1, processes=True))
    with client:
        started = time.perf_counter()
        summary = diagnose_fleet(client, directory, out)
        seconds = time.perf_counter() - started
    n = summary["diagnosed"] + summary["failed"]
    print(
        f"dask: {summary['diagnosed']} valves diagnosed, {summary['failed']} failed, "
        f"in {seconds:.1f} s ({n * 60 / seconds:.1f} recordings per minute)"
    )
    for rank, v in enumerate(summary["valves"], 1):
        found = ", ".join(a["name"] for a in v["advice"]) or "none"
        print(f"{rank:>4}  {v['valve']:<28} {v['severity'] or 'none':>8} {v['priority']:>6.1f}  {found}")


if __name__ == "__main__":
    main(sys.argv)
