"""Bad input, class by class: each case gets the documented exit code and exactly one
``acslam: error:`` line naming the file and the field or line (a usage error adds one
line saying where the help is), never a traceback, and leaves nothing behind: a command
that fails before it starts creates no file and no folder.

Commands run in process through the CLI's own error boundary (click's test runner calls
the same ``main`` the entry point does), so every case costs what its input costs.
"""

from __future__ import annotations

import bz2
import json
import math
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from PIL import Image

from acslam.cli import cli
from acslam.files import atomic_path, write_json
from acslam.grid import FREE, OCCUPIED, GridSpec
from acslam.worlds.mapio import save_map

USAGE, BAD_INPUT = 2, 1


def acslam(*args: object) -> Result:
    return CliRunner().invoke(cli, [str(arg) for arg in args])


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (and every folder, as b"<dir>") with its bytes."""
    return {
        str(p.relative_to(folder)): b"<dir>" if p.is_dir() else p.read_bytes()
        for p in sorted(folder.rglob("*"))
    }


def assert_one_error(result: Result, code: int, *named: str) -> str:
    """The exit code, one error line naming everything in ``named``, no traceback; returns
    the line."""
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(
        result.exception
    )
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    lines = result.stderr.splitlines()
    assert len(lines) == (2 if code == USAGE else 1), lines
    assert lines[0].startswith("acslam: error: "), lines
    for name in named:
        assert name in lines[0], (name, lines[0])
    if code == USAGE:
        assert lines[1].startswith("Try 'acslam") and lines[1].endswith(" --help' for help.")
    return lines[0]


def fails_cleanly(folder: Path, args: list[object], code: int, *named: str) -> str:
    """Run ``acslam args`` in ``folder``; it fails with one error line and changes nothing."""
    before = tree(folder)
    line = assert_one_error(acslam(*args), code, *named)
    assert tree(folder) == before, "the failed command created or changed files"
    return line


# --------------------------------------------------------------------------- files


def room_map(folder: Path, **fields: object) -> Path:
    """A 6 m x 5 m walled room as a map_server map, its YAML fields replaced by ``fields``
    (written as given: YAML text), and a scenario using it; returns the scenario."""
    occupied = np.zeros((100, 120), dtype=bool)
    occupied[:3], occupied[-3:], occupied[:, :3], occupied[:, -3:] = True, True, True, True
    cells = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    save_map(folder / "room", cells, GridSpec(0.0, 0.0, 0.05, 100, 120))
    described = {
        "image": "room.pgm",
        "mode": "trinary",
        "resolution": "0.05",
        "origin": "[0.0, 0.0, 0.0]",
        "negate": "0",
        "occupied_thresh": "0.65",
        "free_thresh": "0.196",
    } | fields
    (folder / "room.yaml").write_text(
        "".join(f"{key}: {value}\n" for key, value in described.items() if value is not None)
    )
    scenario = folder / "room-scenario.yaml"
    scenario.write_text(
        "world: {generator: map_file, file: room.yaml}\nrobots: {starts: [[3.0, 2.5, 0.0]]}\n"
    )
    return scenario


def scenario_file(folder: Path, text: str | bytes, name: str = "bad.yaml") -> Path:
    path = folder / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


@pytest.fixture
def inputs(tmp_path: Path) -> Path:
    folder = tmp_path / "inputs"
    folder.mkdir()
    return folder


THESIS = "world: {generator: thesis, experiment: 1}\n"

# --------------------------------------------------------------------------- reading

READING = {
    "random bytes": (b"name: x\nseed: 1\nworld: \xa2\xff\n", ["not UTF-8", "line 3"]),
    "latin-1 text": (
        "name: caf\xe9\n".encode("latin-1") + THESIS.encode(),
        ["not UTF-8", "line 1"],
    ),
    "control character": (f"name: x\x01\n{THESIS}", ["invalid YAML at line 1", "#x0001"]),
    "NUL byte": (f"{THESIS}seed: 0\x00\n", ["invalid YAML at line 2", "#x0000"]),
    "tab indentation": (f"{THESIS}robots:\n\t- 1\n", ["invalid YAML at line 3"]),
    "unclosed bracket": (f"{THESIS}robots: {{starts: [[1, 2, 0]\nsim: {{}}\n", ["invalid YAML"]),
    "a list, not a mapping": ("- world\n- robots\n", ["must be a YAML mapping"]),
    "empty file": ("", ["must be a YAML mapping"]),
    "unknown key": (f"{THESIS}robts: {{count: 1}}\n", ["robts", "Extra inputs"]),
}


@pytest.mark.parametrize(("content", "named"), READING.values(), ids=READING.keys())
def test_reading_a_scenario(tmp_path: Path, inputs: Path, content, named: list[str]) -> None:
    path = scenario_file(inputs, content)
    args = ["map", "--scenario", path, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, str(path), *named)


def test_a_folder_given_as_the_scenario(tmp_path: Path, inputs: Path) -> None:
    (inputs / "lab.yaml").mkdir()
    args = ["map", "--scenario", inputs / "lab.yaml", "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, "lab.yaml: is a folder, not a scenario file")


def test_a_missing_scenario_file(tmp_path: Path) -> None:
    args = ["map", "--scenario", tmp_path / "none.yaml", "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, "none.yaml: scenario file not found")


def test_reading_an_algorithms_file(tmp_path: Path, inputs: Path) -> None:
    path = scenario_file(inputs, b"localizer: {name: isam2}\nmapper: \xff\n", "algorithms.yaml")
    log = scenario_file(inputs, "ODOM 0 0 0 0 0 0 1 host 0\n", "log.clf")
    args = ["slam", "carmen", log, "--algorithms", path, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, str(path), "not UTF-8", "line 2")


@pytest.mark.parametrize(
    ("content", "named"),
    [
        (b"blocks:\n  - scenarios: [\xe9]\n", ["not UTF-8", "line 2"]),
        ("blocks:\n  - scenarios: [thesis-exp1]\x07\n", ["invalid YAML at line 2"]),
    ],
    ids=["not UTF-8", "control character"],
)
def test_reading_a_grid(tmp_path: Path, inputs: Path, content: bytes | str, named) -> None:
    path = scenario_file(inputs, content, "grid.yaml")
    args = ["experiments", "grid", path, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, str(path), *named)


def test_reading_a_map_files_yaml(tmp_path: Path, inputs: Path) -> None:
    scenario = room_map(inputs)
    (inputs / "room.yaml").write_bytes(b"image: room.pgm\nresolution: \xb5\n")
    args = ["map", "--scenario", scenario, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, str(inputs / "room.yaml"), "not UTF-8", "line 2")


# --------------------------------------------------------------------------- memory budget

BUDGET = {
    # 200,000 x 200,000 cells: the 37 GB the issue saw die in allocation.
    "dungeon at 0.1 mm": (
        "world: {generator: dungeon, resolution_m: 0.0001}\n",
        ["world.resolution_m", "200000 x 200000", "sim.max_grid_cells"],
    ),
    "thesis at 1 mm": (
        "world: {generator: thesis, experiment: 2, resolution_m: 0.001}\n",
        ["world.resolution_m", "40000 x 40000"],
    ),
    "a long vineyard": (
        "world: {generator: vineyard, row_length_m: 100000}\n",
        ["world.resolution_m", "sim.max_grid_cells"],
    ),
    "a small budget": (
        THESIS + "sim: {max_grid_cells: 1000}\n",
        ["world.resolution_m", "800 x 800", "(1e+03)"],
    ),
    "a cell of a kilometre": (
        "world: {generator: dungeon, resolution_m: 1000}\n",
        ["world.resolution_m", "coarser than a tenth of the LiDAR range"],
    ),
    "a cell of a megametre": (
        "world: {generator: thesis, experiment: 1, resolution_m: 1000000}\n",
        ["world.resolution_m", "coarser than a tenth"],
    ),
    "a world smaller than a cell": (
        "world: {generator: dungeon, width_m: 0.01, height_m: 0.01}\n",
        ["world:", "smaller than one cell"],
    ),
}


@pytest.mark.parametrize(("text", "named"), BUDGET.values(), ids=BUDGET.keys())
def test_memory_budget(tmp_path: Path, inputs: Path, text: str, named: list[str]) -> None:
    path = scenario_file(inputs, text)
    args = ["map", "--scenario", path, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, str(path), *named)


def test_memory_budget_of_an_image_world_names_its_file(tmp_path: Path, inputs: Path) -> None:
    scenario = room_map(inputs)
    scenario.write_text(scenario.read_text() + "sim: {max_grid_cells: 11999}\n")
    args = ["map", "--scenario", scenario, "--out", tmp_path / "out"]
    line = fails_cleanly(tmp_path, args, BAD_INPUT, str(scenario), "world.file", "120 x 100")
    # The estimate covers every layer of the run: at least the 18 bytes of the team map.
    assert "about" in line and "over the run's grid layers" in line


def test_memory_budget_of_a_floor_plan(tmp_path: Path, inputs: Path) -> None:
    Image.fromarray(np.full((300, 400), 255, dtype=np.uint8)).save(inputs / "plan.png")
    path = scenario_file(
        inputs,
        "world: {generator: floorplan, file: plan.png}\nsim: {max_grid_cells: 100000}\n",
    )
    args = ["map", "--scenario", path, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, str(path), "world.file", "400 x 300")


# --------------------------------------------------------------------------- map_server fields

MAP_FIELDS = {
    "occupied_thresh: high": ({"occupied_thresh": "high"}, "occupied_thresh: "),
    "occupied_thresh: .nan": ({"occupied_thresh": ".nan"}, "occupied_thresh: "),
    "occupied_thresh above 1": ({"occupied_thresh": "1.5"}, "occupied_thresh: "),
    "free_thresh above occupied_thresh": (
        {"free_thresh": "0.9"},
        "free_thresh must be below occupied_thresh",
    ),
    "negate quoted": ({"negate": '"false"'}, "negate: must be 0 or 1, got 'false'"),
    "negate 2": ({"negate": "2"}, "negate: must be 0 or 1"),
    "resolution 1e300": ({"resolution": "1.0e+300"}, "resolution: a cell of 1e+300 m"),
    "resolution .inf": ({"resolution": ".inf"}, "resolution: "),
    "resolution negative": ({"resolution": "-0.05"}, "resolution: "),
    "origin of two numbers": ({"origin": "[0.0, 0.0]"}, "origin[2]: "),
    "rotated origin": ({"origin": "[0.0, 0.0, 0.5]"}, "origin[2]: rotated maps"),
    "no image": ({"image": None}, "image: Field required"),
    "raw mode": ({"mode": "raw"}, "mode: "),
    "misspelt field": ({"ocupied_thresh": "0.6"}, "ocupied_thresh: Extra inputs"),
}


@pytest.mark.parametrize(("fields", "named"), MAP_FIELDS.values(), ids=MAP_FIELDS.keys())
def test_map_server_fields(tmp_path: Path, inputs: Path, fields: dict, named: str) -> None:
    scenario = room_map(inputs, **fields)
    args = ["map", "--scenario", scenario, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, f"{inputs / 'room.yaml'}: {named}")


@pytest.mark.parametrize(
    ("image", "named"),
    [(None, "room.pgm: map image of"), (b"P5 not a picture", "room.pgm: map image of")],
    ids=["missing", "not an image"],
)
def test_map_server_image(tmp_path: Path, inputs: Path, image: bytes | None, named: str) -> None:
    scenario = room_map(inputs)
    if image is None:
        (inputs / "room.pgm").unlink()
    else:
        (inputs / "room.pgm").write_bytes(image)
    args = ["map", "--scenario", scenario, "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, str(inputs / named))


def test_a_good_map_file_still_loads(tmp_path: Path, inputs: Path) -> None:
    """The fields as map_saver writes them, and as map_server accepts them."""
    scenario = room_map(inputs, negate="false", free_thresh="0.25", occupied_thresh="'0.6'")
    result = acslam("map", "--scenario", scenario, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert "120 x 100 cells at 0.05 m" in result.stdout


# --------------------------------------------------------------------------- simulator clock

CLOCK = {
    "2 s step": ("sim: {dt_s: 2.0}\n", "sensors.odometry.rate_hz (0.05 s)"),
    "a step above the odometry period": ("sim: {dt_s: 0.06}\n", "sensors.odometry.rate_hz"),
    "a fast LiDAR": (
        "sensors: {lidar: {rate_hz: 100}}\n",
        "sensors.lidar.rate_hz (0.01 s)",
    ),
    "a fast camera": ("sensors: {camera: {rate_hz: 60}}\n", "sensors.camera.rate_hz"),
    "a fast controller": (
        "algorithms: {planning: {control_period_s: 0.01}}\n",
        "algorithms.planning.control_period_s (0.01 s)",
    ),
}


@pytest.mark.parametrize(("text", "named"), CLOCK.values(), ids=CLOCK.keys())
def test_simulator_clock(tmp_path: Path, inputs: Path, text: str, named: str) -> None:
    path = scenario_file(inputs, THESIS + text)
    args = ["run", "--scenario", path, "--max-time", "1", "--out", tmp_path / "out"]
    fails_cleanly(tmp_path, args, BAD_INPUT, f"{path}: sim.dt_s: ", named)


# --------------------------------------------------------------------------- short runs


@pytest.mark.parametrize(
    ("max_time", "robots", "scored"),
    [("0.01", 1, False), ("0.01", 3, False), ("0.15", 2, True)],
    ids=["one step, one robot", "one step, three robots", "two steps"],
)
def test_a_run_of_any_length_ends_in_its_metrics(
    tmp_path: Path, max_time: str, robots: int, scored: bool
) -> None:
    out = tmp_path / "out"
    result = acslam("run", "--robots", robots, "--max-time", max_time, "--out", out)
    assert result.exit_code == 0, result.output
    assert result.stderr == ""
    metrics = json.loads((out / "metrics.json").read_text())
    assert (metrics["completed"], metrics["reason"]) == (False, "time limit")
    # One control period (0.1 s) at least, and no more than the limit rounded up to one.
    assert 0.1 - 1e-9 <= metrics["sim_time_s"] <= math.ceil(float(max_time) / 0.1) * 0.1 + 1e-9
    # After one step no estimate lies within the ground truth's span: left out, not made
    # up; after two, the first keyframe's is scored.
    names = [f"robot_{i}" for i in range(robots)]
    assert list(metrics["localization"]) == (names if scored else [])
    assert (out / "report.html").is_file() and (out / "figures" / "map.png").is_file()
    page = (out / "report.html").read_text(encoding="utf-8")
    assert ("Not scored (no ground truth" in page) is not scored


SHORT_OPTIONS = {
    "--max-time nan": (["run", "--max-time", "nan"], "--max-time", "'nan' is not a finite"),
    "--max-time inf": (["run", "--max-time", "inf"], "--max-time", "'inf' is not a finite"),
    "--max-time 0": (["run", "--max-time", "0"], "--max-time", "is not in the range x>0"),
    "--max-time -1": (["run", "--max-time", "-1"], "--max-time", "is not in the range x>0"),
    "--latency-ms nan": (
        ["run", "--distributed", "--latency-ms", "nan"],
        "--latency-ms",
        "not a finite",
    ),
    "--drop-rate -inf": (["run", "--distributed", "--drop-rate", "-inf"], "--drop-rate", ""),
    "--heartbeat-timeout nan": (
        ["serve", "--listen", "tcp/127.0.0.1:1", "--heartbeat-timeout", "nan"],
        "--heartbeat-timeout",
        "not a finite",
    ),
    "--command-timeout inf": (
        ["robot", "--id", "0", "--connect", "tcp/127.0.0.1:1", "--command-timeout", "inf"],
        "--command-timeout",
        "not a finite",
    ),
    "--laser-mount nan": (
        ["serve", "--ros2", "--connect", "tcp/127.0.0.1:1", "--laser-mount", "nan", "0", "0"],
        "--laser-mount",
        "not a finite",
    ),
    "slam mrclam --max-time nan": (
        ["slam", "mrclam", ".", "--out", "x", "--max-time", "nan"],
        "--max-time",
        "not a finite",
    ),
}


@pytest.mark.parametrize(("args", "option", "named"), SHORT_OPTIONS.values(), ids=SHORT_OPTIONS)
def test_float_options_refuse_nan_and_infinity(
    tmp_path: Path, args: list[str], option: str, named: str
) -> None:
    fails_cleanly(tmp_path, args, USAGE, f"'{option}'", named)


# --------------------------------------------------------------------------- output folders


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short one-robot run folder to copy, damage and report on."""
    out = tmp_path_factory.mktemp("finished") / "run"
    result = acslam("run", "--robots", "1", "--max-time", "2", "--out", out)
    assert result.exit_code == 0, result.output
    return out


def test_an_output_folder_that_cannot_be_made(tmp_path: Path) -> None:
    line = fails_cleanly(
        tmp_path, ["map", "--out", "/proc/acslam-out"], BAD_INPUT, "/proc/acslam-out: "
    )
    assert "cannot create the output folder" in line


def test_an_output_folder_through_a_file(tmp_path: Path) -> None:
    (tmp_path / "notes").write_text("a file\n")
    out = tmp_path / "notes" / "run"
    line = fails_cleanly(tmp_path, ["run", "--out", out], BAD_INPUT, str(out))
    assert f"({tmp_path / 'notes'} is a file)" in line


def test_an_output_folder_that_is_a_file(tmp_path: Path) -> None:
    (tmp_path / "run").write_text("a file\n")
    fails_cleanly(tmp_path, ["map", "--out", tmp_path / "run"], USAGE, "'--out'", "is a file")


@pytest.mark.parametrize(
    "args",
    [
        ["map"],
        ["run", "--max-time", "1"],
        ["slam", "carmen", "LOG"],
        ["experiments", "grid", "GRID"],
    ],
    ids=["map", "run", "slam carmen", "experiments grid"],
)
def test_a_folder_that_is_not_empty_is_refused(tmp_path: Path, inputs: Path, args: list) -> None:
    log = scenario_file(inputs, "ODOM 0 0 0 0 0 0 1 host 0\n", "log.clf")
    grid = scenario_file(inputs, "blocks: [{scenarios: [thesis-exp1], robots: [1]}]\n", "g.yaml")
    args = [{"LOG": log, "GRID": grid}.get(arg, arg) for arg in args]
    out = tmp_path / "out"
    (out / "trajectories").mkdir(parents=True)
    (out / "trajectories" / "robot_2.estimated.tum").write_text("# an earlier run's\n")
    line = fails_cleanly(tmp_path, [*args, "--out", out], BAD_INPUT, f"{out}: ", "--overwrite")
    assert "not empty" in line


def test_overwrite_empties_the_folder_first(tmp_path: Path, finished_run: Path) -> None:
    """A 3-robot run's folder reused by a 1-robot run keeps no robot_1, robot_2 files."""
    out = tmp_path / "out"
    shutil.copytree(finished_run, out)
    for name in ("robot_1", "robot_2"):
        shutil.copy(
            out / "trajectories" / "robot_0.estimated.tum",
            out / "trajectories" / f"{name}.estimated.tum",
        )
    result = acslam("run", "--robots", "1", "--max-time", "0.5", "--out", out, "--overwrite")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (out / "trajectories").iterdir()) == [
        "robot_0.estimated.tum",
        "robot_0.groundtruth.tum",
    ]
    assert json.loads((out / "metrics.json").read_text())["sim_time_s"] == pytest.approx(0.5)


@pytest.mark.parametrize("where", [".", ".."], ids=["the current folder", "one above it"])
def test_overwrite_never_empties_the_current_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    (work / "precious.txt").write_text("keep me\n")
    monkeypatch.chdir(work)
    args = ["map", "--out", where, "--overwrite"]
    fails_cleanly(tmp_path, args, BAD_INPUT, f"{where}: --overwrite never empties")


def test_a_command_failing_on_its_input_removes_the_folder_it_made(tmp_path: Path) -> None:
    """``slam carmen`` reads its log inside the output folder's block; a missing log
    leaves neither the folder nor its missing parents."""
    out = tmp_path / "new" / "deeper" / "out"
    args = ["slam", "carmen", tmp_path / "none.clf", "--out", out]
    fails_cleanly(tmp_path, args, BAD_INPUT, "none.clf: log file not found")


# --------------------------------------------------------------------------- report inputs


def _damage_metrics(folder: Path, text: str | bytes) -> None:
    path = folder / "metrics.json"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())


def _edit_metrics(change: Callable[[dict], None]) -> Callable[[Path], None]:
    def damage(folder: Path) -> None:
        metrics = json.loads((folder / "metrics.json").read_text())
        change(metrics)
        write_json(folder / "metrics.json", metrics)

    return damage


def _truncate_record(folder: Path) -> None:
    data = (folder / "run.npz").read_bytes()
    (folder / "run.npz").write_bytes(data[: len(data) // 2])


def _record_without(name: str) -> Callable[[Path], None]:
    def damage(folder: Path) -> None:
        with np.load(folder / "run.npz") as data:
            kept = {k: data[k] for k in data if k != name}
        np.savez_compressed(folder / "run.npz", **kept)

    return damage


def _record_with(name: str, array: np.ndarray) -> Callable[[Path], None]:
    def damage(folder: Path) -> None:
        with np.load(folder / "run.npz") as data:
            arrays = {k: data[k] for k in data} | {name: array}
        np.savez_compressed(folder / "run.npz", **arrays)

    return damage


REPORT_INPUTS = {
    "wrong keys": (lambda f: _damage_metrics(f, '{"a": 1}'), "metrics.json: scenario: Field"),
    "no completed": (_edit_metrics(lambda m: m.pop("completed")), "metrics.json: completed: "),
    "a rate as text": (
        _edit_metrics(lambda m: m["mapping"].update(tpr="high")),
        "metrics.json: mapping.tpr: ",
    ),
    "a stage without p95": (
        _edit_metrics(lambda m: m["server_cycle_ms"]["slam"].pop("p95")),
        "metrics.json: server_cycle_ms.slam.p95: ",
    ),
    "not JSON": (lambda f: _damage_metrics(f, '{\n"scenario": \n'), "metrics.json:3: "),
    "not UTF-8": (lambda f: _damage_metrics(f, b'{"scenario": "\xff"}'), "not UTF-8"),
    "a JSON list": (lambda f: _damage_metrics(f, "[1, 2]"), "metrics.json: "),
    "no metrics": (lambda f: (f / "metrics.json").unlink(), "metrics.json: not found"),
    "a truncated record": (_truncate_record, "run.npz: not a run record"),
    "a record without its map": (_record_without("estimated_values"), "run.npz: not a run"),
    "no record": (lambda f: (f / "run.npz").unlink(), "run.npz: not a run record"),
    "a map of another grid": (_record_with("estimated_values", np.zeros((3, 4))), "grid's shape"),
}


@pytest.mark.parametrize(("damage", "named"), REPORT_INPUTS.values(), ids=REPORT_INPUTS)
def test_report_inputs(tmp_path: Path, finished_run: Path, damage, named: str) -> None:
    folder = tmp_path / "run"
    shutil.copytree(finished_run, folder)
    shutil.rmtree(folder / "figures")
    (folder / "report.html").unlink()
    damage(folder)
    fails_cleanly(tmp_path, ["report", folder], BAD_INPUT, named)
    assert not (folder / "figures").exists() and not (folder / "report.html").exists()


# --------------------------------------------------------------------------- experiment grids

GRIDS = {
    "more robots than starts": (
        "blocks: [{scenarios: [thesis-exp1], robots: [1, 7]}]\n",
        ["blocks.0.robots: ", "7 robots requested but only 3"],
    ),
    "a broken scenario file": (
        "blocks:\n  - {scenarios: [thesis-exp1], robots: [1]}\n"
        "  - {scenarios: [thesis-exp2, broken.yaml], robots: [1]}\n",
        ["blocks.1.scenarios.1: ", "broken.yaml: not UTF-8"],
    ),
    "a scenario with a bad field": (
        "blocks: [{scenarios: [clock.yaml], robots: [1]}]\n",
        ["blocks.0.scenarios.0: ", "clock.yaml: sim.dt_s: "],
    ),
    "a world too large": (
        "blocks: [{scenarios: [huge.yaml], robots: [1]}]\n",
        ["blocks.0.scenarios.0: ", "huge.yaml: world.resolution_m: "],
    ),
    "the largest team of a block": (
        "blocks: [{scenarios: [thesis-exp1, two.yaml], robots: [1, 2, 3]}]\n",
        ["blocks.0.robots: ", "two.yaml: 3 robots requested but only 2"],
    ),
    "a missing scenario": (
        "blocks: [{scenarios: [absent.yaml]}]\n",
        ["blocks.0.scenarios.0: ", "neither a built-in scenario"],
    ),
}


@pytest.mark.parametrize(("text", "named"), GRIDS.values(), ids=GRIDS)
def test_every_cell_of_a_grid_is_checked_first(
    tmp_path: Path, inputs: Path, text: str, named: list[str]
) -> None:
    scenario_file(inputs, b"world: \xff\n", "broken.yaml")
    scenario_file(inputs, THESIS + "sim: {dt_s: 1.0}\n", "clock.yaml")
    scenario_file(
        inputs, "world: {generator: thesis, experiment: 1, resolution_m: 0.001}\n", "huge.yaml"
    )
    scenario_file(inputs, THESIS + "robots: {starts: [[2, 2, 0], [2, 3, 0]]}\n", "two.yaml")
    grid = scenario_file(inputs, text, "grid.yaml")
    args = ["experiments", "grid", grid, "--out", tmp_path / "out", "--max-time", "1"]
    fails_cleanly(tmp_path, args, BAD_INPUT, f"{grid}: ", *named)


# --------------------------------------------------------------------------- strict JSON

NON_FINITE = {
    "infinity": (math.inf, None),
    "minus infinity": (-math.inf, None),
    "NaN": (math.nan, None),
    "NumPy NaN": (np.float64("nan"), None),
    "nested": ({"a": [1.5, math.inf, {"b": (math.nan, 2)}]}, {"a": [1.5, None, {"b": [None, 2]}]}),
}


@pytest.mark.parametrize(("value", "expected"), NON_FINITE.values(), ids=NON_FINITE)
def test_json_is_strict(tmp_path: Path, value: object, expected: object) -> None:
    path = write_json(tmp_path / "m.json", {"value": value})

    def refuse(constant: str) -> None:
        raise AssertionError(f"{constant} is not JSON")

    assert json.loads(path.read_text(), parse_constant=refuse) == {"value": expected}


def test_a_one_robot_runs_metrics_are_strict_json(finished_run: Path) -> None:
    def refuse(constant: str) -> None:
        raise AssertionError(f"{constant} is not JSON")

    metrics = json.loads((finished_run / "metrics.json").read_text(), parse_constant=refuse)
    assert metrics["robots"] == 1 and metrics["safety"]["min_robot_distance_m"] is None
    page = (finished_run / "report.html").read_text(encoding="utf-8")
    assert "distance: one robot has no other to come close to" in page


# --------------------------------------------------------------------------- atomic writes


def test_every_file_of_a_run_is_written_by_renaming(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each file of a run folder arrives whole: written under a temporary name in its
    folder, then renamed into place, and no temporary file is left."""
    renamed: list[tuple[Path, Path]] = []
    replace = os.replace

    def recording_replace(source: str | Path, target: str | Path) -> None:
        renamed.append((Path(source), Path(target)))
        replace(source, target)

    monkeypatch.setattr(os, "replace", recording_replace)
    out = tmp_path / "out"
    assert acslam("run", "--robots", "2", "--max-time", "0.5", "--out", out).exit_code == 0
    written = {p for p in out.rglob("*") if p.is_file()}
    assert {target for _, target in renamed} == written
    assert all(source.parent == target.parent for source, target in renamed)
    assert len(written) >= 12  # config, metrics, map, run record, 4 TUM files, report, figures


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    path = write_json(tmp_path / "metrics.json", {"old": True})
    with pytest.raises(RuntimeError), atomic_path(path) as temporary:
        temporary.write_text('{"new": ')
        raise RuntimeError("disk full")
    assert json.loads(path.read_text()) == {"old": True}
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.json"]


# --------------------------------------------------------------------------- log junk


def _flaser(stamp: float) -> str:
    return f"FLASER 3 1.5 1.5 1.5 1 2 0.5 1 2 0.5 100.0 host {stamp}"


def _log(folder: Path, lines: list[bytes], name: str = "log.clf") -> Path:
    data = b"\n".join(lines) + b"\n"
    path = folder / name
    path.write_bytes(bz2.compress(data) if name.endswith(".bz2") else data)
    return path


GOOD = [b"ODOM 0 0 0 0 0 0 100.0 host 0.1", _flaser(0.2).encode(), _flaser(0.4).encode()]
NAN_ODOM = b"ODOM 1 1 nan 0 0 0 100.0 host 0.3"
LOG_JUNK = {
    "one non-ASCII line": (
        [*GOOD[:2], b"\xff\xfe junk \x80", GOOD[2]],
        "log.clf",
        ["log.clf:3: skipped non-ASCII line"],
    ),
    "non-ASCII in a compressed log": (
        [GOOD[0], "ODOM 0 0 0 0 0 0 100.0 h\u00f6st 0.1".encode(), *GOOD[1:]],
        "log.clf.bz2",
        ["log.clf.bz2:2: skipped non-ASCII line"],
    ),
    "twenty NaN lines": (
        [GOOD[0], *[NAN_ODOM] * 20, *GOOD[1:]],
        "log.clf",
        ["log.clf:2: skipped ODOM: non-finite value (20 lines: 2, 3, 4, 5, 6, ...)"],
    ),
    "two kinds": (
        [GOOD[0], NAN_ODOM, b"\xe9", NAN_ODOM, b"\xe9", *GOOD[1:]],
        "log.clf",
        [
            "log.clf:2: skipped ODOM: non-finite value (2 lines: 2, 4)",
            "log.clf:3: skipped non-ASCII line (2 lines: 3, 5)",
        ],
    ),
}


@pytest.mark.parametrize(("lines", "name", "warned"), LOG_JUNK.values(), ids=LOG_JUNK)
def test_log_junk_is_skipped_counted_and_warned_once_per_kind(
    tmp_path: Path, inputs: Path, lines: list[bytes], name: str, warned: list[str]
) -> None:
    log = _log(inputs, lines, name)
    result = acslam("slam", "carmen", log, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert result.stderr.splitlines() == [f"acslam: warning: {log.parent}/{w}" for w in warned]
    skipped = json.loads((tmp_path / "out" / "metrics.json").read_text())["skipped_lines"]
    assert skipped["count"] == len(lines) - len(GOOD)


def test_a_log_of_junk_only(tmp_path: Path, inputs: Path) -> None:
    log = _log(inputs, [b"\xff" * 10, NAN_ODOM])
    result = acslam("slam", "carmen", log, "--out", tmp_path / "out")
    assert result.exit_code == BAD_INPUT
    lines = result.stderr.splitlines()
    assert [line.split(": ")[1] for line in lines[:2]] == ["warning", "warning"]
    assert lines[2:] == [f"acslam: error: {log}: no usable FLASER line"]
    assert not (tmp_path / "out").exists()


def test_a_folder_given_as_the_log(tmp_path: Path) -> None:
    fails_cleanly(tmp_path, ["slam", "carmen", tmp_path, "--out", "x"], USAGE, "'LOG'")


# --------------------------------------------------------------------------- one error format

USAGE_ERRORS = {
    "no such command": (["explore"], "No such command 'explore'", "Try 'acslam --help'"),
    "no such option": (["run", "--robot", "2"], "No such option '--robot'", "acslam run"),
    "a count of zero": (["run", "--robots", "0"], "'--robots': 0 is not in the range", "run"),
    "an unknown planner": (["run", "--planner", "teleport"], "'--planner': 'teleport'", "run"),
    "a missing argument": (["report"], "Missing argument 'RUN_DIR'", "acslam report"),
    "an option without its partner": (["run", "--ros2"], "--ros2 needs --distributed", "run"),
    "a nested command": (["slam", "carmen"], "Missing argument 'LOG'", "acslam slam carmen"),
    "a bad choice": (["experiments", "thesis", "--grid", "x", "--out", "o"], "'--grid'", "thesis"),
}


@pytest.mark.parametrize(("args", "named", "where"), USAGE_ERRORS.values(), ids=USAGE_ERRORS)
def test_usage_errors(tmp_path: Path, args: list[str], named: str, where: str) -> None:
    result = acslam(*args)
    assert_one_error(result, USAGE, named)
    assert where in result.stderr.splitlines()[1]


def test_the_entry_point_speaks_the_same_format(tmp_path: Path) -> None:
    """Through ``python -m acslam.cli``: the program is called acslam, a usage error is
    two lines and exit 2, bad input one line and exit 1."""
    usage = subprocess.run(
        [sys.executable, "-m", "acslam.cli", "run", "--robots", "0"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert usage.returncode == USAGE
    assert usage.stderr.splitlines() == [
        "acslam: error: Invalid value for '--robots': 0 is not in the range x>=1.",
        "Try 'acslam run --help' for help.",
    ]
    bad = subprocess.run(
        [sys.executable, "-m", "acslam.cli", "map", "--scenario", str(tmp_path), "--out", "o"],
        capture_output=True,
        text=True,
        check=False,
        cwd=tmp_path,
    )
    assert bad.returncode == BAD_INPUT
    assert bad.stderr.splitlines() == [
        f"acslam: error: {tmp_path}: is a folder, not a scenario file"
    ]
    assert list(tmp_path.iterdir()) == []
