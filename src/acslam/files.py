"""Reading acslam's input files and writing its outputs, each in one place.

Reading: every YAML file a user gives (scenario, algorithms, experiment grid, map_server
map) goes through :func:`read_yaml`, so a folder, a missing file, bytes that are not
UTF-8 and YAML syntax errors (control characters included) all become one
:class:`~acslam.errors.ConfigError` naming the file and the line.

Writing: every file goes to a temporary name in its folder first and is renamed into place
(:func:`atomic_path`), so a run stopped at any moment leaves whole files or none, never a
truncated one. JSON is written strictly (:func:`write_json`): a number that is not finite
is ``null``, as the JSON specification has no infinity or NaN.

Output folders: :func:`prepare_output_folder` makes the folder a command writes, refusing
one that holds something else unless told to overwrite it.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from acslam.errors import ConfigError, DataError

if TYPE_CHECKING:
    from PIL import Image

_temporary_names = itertools.count()


def read_text(path: Path, what: str) -> str:
    """The UTF-8 text of the file ``what`` names (e.g. "scenario file"), or ConfigError."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(path, "", f"is a folder, not a {what}")
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(path, "", f"{what} not found") from None
    except OSError as exc:
        raise ConfigError(path, "", f"cannot read the {what} ({exc.strerror})") from None
    return _decode_utf8(data, path)


def _decode_utf8(data: bytes, source: str | Path) -> str:
    """``data`` as UTF-8 text, or a ConfigError naming the line of the first bad byte."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ConfigError(
            source, "", f"not UTF-8 text (byte 0x{data[exc.start]:02x} at line {line})"
        ) from None


def parse_yaml(text: str, source: str | Path) -> Any:
    """YAML text as data; a syntax error or a character YAML does not allow is a
    ConfigError naming the line."""
    try:
        return yaml.safe_load(text)
    except yaml.reader.ReaderError as exc:
        line = text[: exc.position].count("\n") + 1
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        raise ConfigError(
            source, "", f"invalid YAML at line {line}: character #x{code:04x}: {exc.reason}"
        ) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = f": {exc.problem}" if exc.problem else ""
        raise ConfigError(source, "", f"invalid YAML{where}{problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(source, "", f"invalid YAML ({exc})") from None


def read_yaml(path: Path, what: str) -> Any:
    """The data of the YAML file ``what`` names (:func:`read_text`, :func:`parse_yaml`)."""
    return parse_yaml(read_text(path, what), path)


def read_json(path: Path, what: str) -> Any:
    """The data of a JSON file acslam wrote, or a DataError naming the file and line."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise DataError(path, f"{what} not found") from None
    except IsADirectoryError:
        raise DataError(path, f"is a folder, not a {what}") from None
    except OSError as exc:
        raise DataError(path, f"cannot read the {what} ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise DataError(path, f"the {what} is not UTF-8 text (byte {exc.start})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataError(path, f"the {what} is not valid JSON ({exc.msg})", exc.lineno) from None


@contextmanager
def open_image(path: Path, what: str) -> Iterator[Image.Image]:
    """The image file ``what`` names, opened (pixels are read when first used), or a
    DataError naming it; an image that turns out damaged while read is one too."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise DataError(path, f"{what} not found")
    try:
        with Image.open(path) as image:
            yield image
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as exc:
        raise DataError(path, f"{what} cannot be read ({exc})") from None


# --------------------------------------------------------------------------- writing


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; renamed to ``path`` when the block
    ends without an exception, removed otherwise. It keeps ``path``'s suffix, which
    writers such as matplotlib, Pillow and NumPy read the format from."""
    path = Path(path)
    temporary = path.with_name(
        f".{path.stem}.{os.getpid()}-{next(_temporary_names)}.tmp{path.suffix}"
    )
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def write_text(path: Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically; returns ``path``."""
    with atomic_path(path) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return Path(path)


def strict_json(value: Any) -> Any:
    """``value`` with every float that is not finite replaced by None (JSON ``null``)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: strict_json(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(item) for item in value]
    return value


def write_json(path: Path, data: Any, indent: int | None = 2) -> Path:
    """Write ``data`` as strict JSON (``null`` for infinities and NaN), atomically."""
    return write_text(path, json.dumps(strict_json(data), indent=indent, allow_nan=False))


def write_yaml(path: Path, data: Any) -> Path:
    """Write ``data`` as YAML in its own key order, atomically."""
    return write_text(path, yaml.safe_dump(data, sort_keys=False))


# --------------------------------------------------------------------------- output folders


def prepare_output_folder(
    folder: Path, *, overwrite: bool = False, resumable: str | None = None
) -> list[Path]:
    """Make ``folder`` for a command's outputs, or a DataError naming it; returns the
    folders it created (``folder`` and missing parents, innermost first).

    A folder that already holds files is refused, so that files of an earlier run can
    never sit beside this one's, unless ``overwrite`` (it is emptied first; never the
    current folder or one above it) or it holds the file ``resumable`` names (a sweep's
    own folder, which it resumes)."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise DataError(folder, "exists and is not a folder")
    if folder.is_dir() and any(folder.iterdir()):
        if resumable is not None and (folder / resumable).is_file():
            return []
        if not overwrite:
            raise DataError(
                folder,
                "the output folder is not empty: give a new one, or --overwrite to empty it first",
            )
        if Path.cwd().resolve().is_relative_to(folder.resolve()):
            raise DataError(folder, "--overwrite never empties the current folder or one above it")
        for entry in folder.iterdir():
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
        return []
    missing = [p for p in [folder, *folder.parents] if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _remove_empty(missing)
        blocked = next((p for p in folder.parents if p.exists() and not p.is_dir()), None)
        problem = f"{blocked} is a file" if blocked is not None else exc.strerror
        raise DataError(folder, f"cannot create the output folder ({problem})") from None
    return missing


def _remove_empty(folders: list[Path]) -> None:
    for made in folders:
        with suppress(OSError):
            made.rmdir()


@contextmanager
def output_folder(
    folder: Path, *, overwrite: bool = False, resumable: str | None = None
) -> Iterator[Path]:
    """:func:`prepare_output_folder` for a block that writes into it: if the block fails
    before writing anything, the folders made for it are removed again, so a command
    that fails before it starts leaves nothing behind."""
    made = prepare_output_folder(folder, overwrite=overwrite, resumable=resumable)
    try:
        yield Path(folder)
    except BaseException:
        _remove_empty(made)
        raise
