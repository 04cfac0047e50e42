"""Fixed runs whose ``metrics.json`` must not change under a refactor, and their comparison.

``python tools/behaviour_runs.py run OUT`` writes the set to ``OUT/<name>/``;
``python tools/behaviour_runs.py compare A B`` diffs two such folders apart from wall-clock
fields and exits 1 on any difference. Run ``run`` twice on the same commit first: the set
is bit-reproducible, so any difference after a change is the change's.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "datasets"

# Fields that measure the machine, not the computation, and what records when and how a
# run was made.
WALL_CLOCK_KEYS = {
    "provenance",
    "wall_time_s",
    "real_time_factor",
    "server_cycle_ms",
    "isam2_update_ms",
    "slam_time_s",
    "mapping_time_s",
    "mean_s",  # MRCLAM's iSAM2 update times
    "p95_s",
}


def commands() -> dict[str, list[str]]:
    """Run name -> acslam arguments (before ``--out``)."""
    runs = {
        f"exp{e}-r{r}": ["run", "--scenario", f"thesis-exp{e}", "--robots", str(r), "--seed", "0"]
        for e in (1, 2, 3, 4)
        for r in (1, 3)
    }
    runs["vineyard-r3"] = ["run", "--scenario", "vineyard", "--robots", "3"]
    runs["carmen-intel"] = ["slam", "carmen", str(SHARED / "intel_lab_carmen" / "intel.clf.bz2")]
    runs["mrclam-7"] = ["slam", "mrclam", str(SHARED / "mrclam_dataset7")]
    return runs


def run_all(out: Path, workers: int) -> None:
    def one(item: tuple[str, list[str]]) -> str:
        name, args = item
        folder = out / name
        cmd = [sys.executable, "-m", "acslam.cli", *args, "--out", str(folder)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        return f"{name}: exit {done.returncode}"

    with ThreadPoolExecutor(workers) as pool:
        for line in pool.map(one, commands().items()):
            print(line, flush=True)


def _strip(value: object) -> object:
    if isinstance(value, dict):
        return {k: _strip(v) for k, v in value.items() if k not in WALL_CLOCK_KEYS}
    if isinstance(value, list):
        return [_strip(v) for v in value]
    return value


def _leaves(value: object, prefix: str = "") -> dict[str, object]:
    if isinstance(value, dict):
        out: dict[str, object] = {}
        for k, v in value.items():
            out.update(_leaves(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    if isinstance(value, list):
        out = {}
        for i, v in enumerate(value):
            out.update(_leaves(v, f"{prefix}[{i}]"))
        return out
    return {prefix: json.dumps(value)}


def compare(a: Path, b: Path) -> int:
    differing = 0
    for name in commands():
        files = [a / name / "metrics.json", b / name / "metrics.json"]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            print(f"{name}: missing {', '.join(missing)}")
            differing += 1
            continue
        left, right = (_leaves(_strip(json.loads(f.read_text()))) for f in files)
        diffs = sorted(k for k in left.keys() | right.keys() if left.get(k) != right.get(k))
        if diffs:
            differing += 1
            print(f"{name}: {len(diffs)} of {len(left)} fields differ")
            for key in diffs[:20]:
                print(f"  {key}: {left.get(key)} -> {right.get(key)}")
        else:
            print(f"{name}: identical ({len(left)} fields)")
    return 1 if differing else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run")
    run.add_argument("out", type=Path)
    run.add_argument("--workers", type=int, default=2)
    cmp = sub.add_parser("compare")
    cmp.add_argument("a", type=Path)
    cmp.add_argument("b", type=Path)
    args = parser.parse_args()
    if args.command == "run":
        run_all(args.out, args.workers)
    else:
        sys.exit(compare(args.a, args.b))


if __name__ == "__main__":
    main()
