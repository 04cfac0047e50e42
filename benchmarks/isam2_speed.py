"""iSAM2 update and landmark association time against graph size (a benchmark, not a test).

Three simulated robots drive overlapping circles through a landmark grid up to 10,000
keyframes in all; one back-end update per server cycle (one keyframe per robot). Prints
per 500-keyframe bucket the update's mean and p95, its p95 per keyframe, and the
association's mean and p95 per frame; then how much the last bucket's p95 per keyframe
exceeds the first's. The measuring code is
:func:`acslam.benchmarks.isam2.measure_isam2_updates`, which ``acslam bench`` calls too.

Run: ``python benchmarks/isam2_speed.py [keyframes [robots [seed]]]``
"""

import sys

from acslam.benchmarks.isam2 import measure_isam2_updates


def main() -> None:
    keyframes, robots, seed = (
        int(a) for a in (sys.argv[1:] + ["10000", "3", "0"][len(sys.argv) - 1 :])
    )
    result = measure_isam2_updates(keyframes, robots, seed)
    print(f"{robots} robots, {keyframes} keyframes, seed {seed}, {result['landmarks']} landmarks")
    print("keyframes    updates  update mean  p95   p95/keyframe   association mean  p95 (ms)")
    for b in result["buckets"]:
        print(
            f"{b['from']:>5}-{b['to']:<6} {b['updates']:>6} {b['mean_ms']:>10.1f} "
            f"{b['p95_ms']:>6.1f} {b['per_keyframe_p95_ms']:>10.1f} "
            f"{b['association_mean_ms']:>16.2f} {b['association_p95_ms']:>6.2f}"
        )
    first, last = result["buckets"][0], result["buckets"][-1]
    print(
        f"all: update p95 {result['p95_ms']:.1f} ms, per keyframe p95 "
        f"{result['per_keyframe_p95_ms']:.1f} ms; last/first bucket p95 per keyframe "
        f"{last['per_keyframe_p95_ms'] / first['per_keyframe_p95_ms']:.2f}; "
        f"worst final position error {result['final_position_error_m']:.3f} m"
    )


if __name__ == "__main__":
    main()
