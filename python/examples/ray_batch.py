"""Runs every line of a visnav batch manifest as one Ray task.

    python ray_batch.py MANIFEST.jsonl [--num-cpus N] [--address ADDR] [--skip-existing]

Each task calls ``visnav.run_manifest_line(manifest, index)``, the library function behind
``visnav batch MANIFEST --index N``: it writes exactly what the CLI writes (``DIR/poses.txt``,
``DIR/report.json``, ``DIR/status.json``, each atomically). A line that fails writes its
``status.json`` with the error and is reported here; the exit code is 0 when every line is done,
2 when a line failed on bad input, 3 when one failed on I/O (the retryable kind), as ``visnav
batch --all``. Without ``--address`` a local Ray instance is
started with ``--num-cpus`` CPUs (Ray's local mode is gone from Ray 2.5x). Every worker needs the manifest and the data at the same paths (a shared file
system), and the ``visnav`` package installed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import ray

import visnav

EXIT_BAD_INPUT = 2
EXIT_IO = 3


@ray.remote
def run_line(manifest: str, index: int, skip_existing: bool) -> dict:
    """One manifest line; the outcome as a dict, never an exception (so every line reports)."""
    try:
        status = visnav.run_manifest_line(manifest, index, skip_existing=skip_existing)
        return {"index": index, "ok": True, "status": status}
    except (OSError, ValueError) as e:
        # FileNotFoundError and ValueError: bad input (do not retry); other OSError: I/O (retry)
        io = isinstance(e, OSError) and not isinstance(e, FileNotFoundError)
        return {"index": index, "ok": False, "io": io, "error": str(e)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("manifest", type=Path)
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs for a local Ray instance")
    p.add_argument("--address", default=None, help="an existing Ray cluster (ray.init address)")
    p.add_argument("--skip-existing", action="store_true", help="skip lines whose status.json says ok")
    args = p.parse_args(argv)
    manifest = str(args.manifest.resolve())
    try:
        n = visnav.manifest_len(manifest)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_IO if isinstance(e, OSError) and not isinstance(e, FileNotFoundError) else EXIT_BAD_INPUT
    init = {"address": args.address} if args.address else {"num_cpus": args.num_cpus}
    ray.init(include_dashboard=False, log_to_driver=True, **init)
    try:
        results = ray.get([run_line.remote(manifest, i, args.skip_existing) for i in range(n)])
    finally:
        ray.shutdown()
    code = 0
    for r in sorted(results, key=lambda r: r["index"]):
        if r["ok"]:
            s = r["status"]
            print(f"run {r['index']}: {s['status']}, {s.get('frames', '-')} frames, {s.get('wall_s', 0.0):.2f} s")
        else:
            print(f"error: run {r['index']}: {r['error']}", file=sys.stderr)
            code = EXIT_IO if r["io"] else max(code, EXIT_BAD_INPUT)
    return code


if __name__ == "__main__":
    sys.exit(main())
