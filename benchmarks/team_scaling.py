"""The server cycle against team size and elapsed time on a real floor plan (a benchmark,
not a test).

Runs ``examples/floorplan-office-a.yaml`` (IPA office_a, 1,528 m² reachable; the plan is
read from ``../shared``) with 1, 3 and 10 robots for the same simulated time, or until
explored, and prints per team size the server cycle's mean, p95, p99 and max, its p95 over
the first and the last tenth of the run, each stage's p95 and the real-time factor; the
ratios are against the one-robot run, measured in the same process. Writes
``team_scaling.json`` and ``team_scaling.png`` (the cycle's p95 per 10 s of simulated
time, one line per team size) to ``--out``. The measuring code is
:func:`acslam.benchmarks.team_scaling.measure_team_scaling`; ``acslam bench`` runs the
same on the built-in ``dungeon-40``.

Run: ``python benchmarks/team_scaling.py [--max-time 600] [--teams 1 3 10] [--out DIR]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

from acslam import files
from acslam.benchmarks.team_scaling import (
    TEAM_SIZES,
    measure_team_scaling,
    plot_team_scaling,
)

SCENARIO = Path(__file__).resolve().parents[1] / "examples" / "floorplan-office-a.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--max-time", type=float, default=600.0, help="simulated seconds")
    parser.add_argument("--teams", type=int, nargs="+", default=list(TEAM_SIZES))
    parser.add_argument("--out", type=Path, default=Path("."))
    args = parser.parse_args()
    result = measure_team_scaling(SCENARIO, args.max_time, args.teams)
    period_ms = result["control_period_ms"]
    base_p95_ms = result["teams"][0]["cycle"]["p95_ms"]
    print(f"{SCENARIO.name}, at most {args.max_time:g} s simulated, period {period_ms:g} ms")
    print(
        "robots  sim s  explored  RTF   cycle mean  p95  p99   max (ms)  p95/period  "
        "p95/first team  first tenth p95  last tenth p95  stage p95 (ms)"
    )
    for team in result["teams"]:
        c = team["cycle"]
        stages = ", ".join(f"{k} {v:.0f}" for k, v in team["stages"].items())
        print(
            f"{team['robots']:>6} {team['sim_time_s']:>6.0f} "
            f"{100 * team['explored_fraction']:>8.1f}% "
            f"{team['real_time_factor']:>5.2f} {c['mean_ms']:>10.1f} {c['p95_ms']:>5.0f} "
            f"{c['p99_ms']:>4.0f} {c['max_ms']:>5.0f} {c['p95_ms'] / period_ms:>11.2f} "
            f"{c['p95_ms'] / base_p95_ms:>15.2f} {c['first_tenth_p95_ms']:>16.0f} "
            f"{c['last_tenth_p95_ms']:>15.0f}  {stages}"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    files.write_json(args.out / "team_scaling.json", result, indent=1)
    print(f"wrote {plot_team_scaling(result, args.out / 'team_scaling.png')}")


if __name__ == "__main__":
    main()
