"""Loop-closure candidate search against graph size (a benchmark, not a test).

Three robots lap one corridor up to 10,000 keyframes; prints per 1000-keyframe bucket the
index's mean and p95 search time and the exhaustive search's mean on the same state
(timed every 25th search), and their ratio. The measuring code is
:func:`acslam.benchmarks.loop_closure.measure_loop_candidate_search`, which
``acslam bench`` calls too.

Run: ``python benchmarks/loop_closure_speed.py [keyframes [robots [seed]]]``
"""

import sys

from acslam.benchmarks.loop_closure import measure_loop_candidate_search


def main() -> None:
    keyframes, robots, seed = (
        int(a) for a in (sys.argv[1:] + ["10000", "3", "0"][len(sys.argv) - 1 :])
    )
    result = measure_loop_candidate_search(keyframes, robots, seed)
    print(
        f"{robots} robots, {keyframes} keyframes, seed {seed}, {result['pairs_tried']} pairs tried"
    )
    print("keyframes    searches  index mean  p95   exhaustive mean (ms)  ratio")
    for b in result["buckets"]:
        reference = b["exhaustive_mean_ms"]
        compared = (
            f"{reference:>14.1f} {b['index_mean_ms'] / reference:>12.4f}" if reference else "-"
        )
        print(
            f"{b['from']:>5}-{b['to']:<6} {b['searches']:>6} {b['index_mean_ms']:>11.2f} "
            f"{b['index_p95_ms']:>5.2f} {compared}"
        )


if __name__ == "__main__":
    main()
