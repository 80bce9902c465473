"""``tdmon examples DIR``: the example files that come with tdmon, copied into a folder.

An installed tdmon carries the checkout's ``config/`` (well files, daemon files, the broker's
and Foxglove's configuration), ``data/`` (the Volve F-4 logs, the thesis's tribometer data) and
``replays/`` (recordings, scenarios, expectations) as package data in ``tdmon/examples/``; in a
checkout that folder links to them. Copied into DIR with the same layout, the relative paths
between them hold (a daemon file's ``well = "../wells/..."``, an expectation's ``config``), so
the README's commands run from DIR as they do from a checkout.
"""

from __future__ import annotations

import argparse
from importlib.resources import files
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

from tdmon.errors import TdmonError

#: The folders copied, and what they hold (for the summary).
FOLDERS = {"config": "well and daemon files", "data": "logs and lab data",
           "replays": "recordings, scenarios, expectations"}


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``examples``."""
    examples = subparsers.add_parser(
        "examples", help="copy the example wells, daemon files, data and replays into a folder",
        description="Copy the example files that come with tdmon into FOLDER: config/ (well "
                    "and daemon files), data/ (the Volve F-4 logs, tribometer data), replays/ "
                    "(recordings, scenarios, expectations), as laid out in a checkout, so "
                    "that the README's commands run from FOLDER. Files already there with "
                    "the same content are left as they are.")
    examples.add_argument("folder", type=Path, metavar="FOLDER",
                          help="where to copy them (created if missing)")
    examples.add_argument("--force", action="store_true",
                          help="overwrite files of the same name that differ (otherwise: "
                               "an error naming them, nothing copied)")
    examples.set_defaults(func=_copy_examples)


def example_files() -> dict[str, Traversable]:
    """Every example file by its path in the layout (``config/wells/volve-f4.toml``, ...).

    Raises
    ------
    TdmonError
        This installation has no example files.
    """
    root = files("tdmon") / "examples"
    found: dict[str, Traversable] = {}

    def walk(folder: Traversable, prefix: str) -> None:
        for entry in folder.iterdir():
            if entry.name == "__pycache__":
                continue
            if entry.is_dir():
                walk(entry, f"{prefix}{entry.name}/")
            else:
                found[f"{prefix}{entry.name}"] = entry

    for name in FOLDERS:
        folder = root / name
        if folder.is_dir():
            walk(folder, f"{name}/")
    if not found:
        raise TdmonError("this installation of tdmon has no example files (tdmon/examples is "
                         "missing or empty): install it from its wheel, or use a checkout")
    return dict(sorted(found.items()))


def _copy_examples(args: argparse.Namespace) -> int:
    folder: Path = args.folder
    sources = example_files()
    contents = {name: source.read_bytes() for name, source in sources.items()}
    differing = [name for name, data in contents.items()
                 if (folder / name).is_file() and (folder / name).read_bytes() != data]
    clashing = [name for name in contents if (folder / name).exists()
                and not (folder / name).is_file()]
    if clashing:
        raise TdmonError(f"{folder / clashing[0]} is in the way (not a file)")
    if differing and not args.force:
        more = f" and {len(differing) - 1} more" if len(differing) > 1 else ""
        raise TdmonError(f"{folder / differing[0]}{more} already there with other contents: "
                         "give --force to overwrite, or another folder")
    copied = 0
    for name, data in contents.items():
        target = folder / name
        if target.is_file() and target.read_bytes() == data:
            continue
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        except OSError as exc:
            raise TdmonError(f"cannot write {target}: {exc.strerror or exc}") from exc
        copied += 1
    size = sum(map(len, contents.values()))
    kept = len(contents) - copied
    note = f" ({kept} already there)" if kept else ""
    print(f"{folder}: {len(contents)} example files, {size / 1e6:.1f} MB{note}")
    for name, what in FOLDERS.items():
        count = sum(1 for path in contents if path.startswith(f"{name}/"))
        print(f"  {name + '/':9} {count:3d} files: {what}")
    print(f"from there the README's commands run as in a checkout, e.g.\n"
          f"  cd {folder} && tdmon model loads --well config/wells/aadnoy-example-7-1.toml")
    return 0
