"""iSAM2 update time per keyframe against graph size (a benchmark, not a test).

Three simulated robots drive overlapping circles through a landmark grid up to 3000
keyframes in all; one back-end update per server cycle (one keyframe per robot). Prints
mean and p95 update time per 500-keyframe bucket. The measuring code is
:func:`acslam.benchmarks.isam2.measure_isam2_updates`, which ``acslam bench`` can call too.

Run: ``python benchmarks/isam2_speed.py [keyframes [robots [seed]]]``
"""

import sys

from acslam.benchmarks.isam2 import measure_isam2_updates


def main() -> None:
    keyframes, robots, seed = (
        int(a) for a in (sys.argv[1:] + ["3000", "3", "0"][len(sys.argv) - 1 :])
    )
    result = measure_isam2_updates(keyframes, robots, seed)
    print(f"{robots} robots, {keyframes} keyframes, seed {seed}, {result['landmarks']} landmarks")
    print("keyframes   updates  mean ms   p95 ms   max ms")
    for b in result["buckets"]:
        print(
            f"{b['from']:>5}-{b['to']:<5} {b['updates']:>7} {b['mean_ms']:>8.1f} "
            f"{b['p95_ms']:>8.1f} {b['max_ms']:>8.1f}"
        )
    print(
        f"all: mean {result['mean_ms']:.1f} ms, p95 {result['p95_ms']:.1f} ms per update; "
        f"per keyframe mean {result['per_keyframe_mean_ms']:.1f} ms, "
        f"p95 {result['per_keyframe_p95_ms']:.1f} ms; "
        f"worst final position error {result['final_position_error_m']:.3f} m"
    )


if __name__ == "__main__":
    main()
