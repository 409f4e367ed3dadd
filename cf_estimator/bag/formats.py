"""Which reader opens a path: :func:`open_bag` — a ROS 1 ``.bag``, a ROS 2 bag directory or bare
``.mcap`` (:mod:`cf_estimator.bag.reader`, over ``rosbags``; cut short: what is readable,
:mod:`cf_estimator.bag.salvage`), a PX4 ``.ulg`` log (:mod:`cf_estimator.bag.ulog`) or an
ArduPilot ``.bin`` DataFlash log (:mod:`cf_estimator.bag.dataflash`). Every failure is a
:class:`~cf_estimator.bag.types.BagError` naming the file. The format readers build on
:mod:`cf_estimator.bag.reader`'s types and never import this module: no import circle.
"""

from __future__ import annotations

import os
from pathlib import Path

from rosbags.highlevel import AnyReader

from cf_estimator.bag.reader import InputBag
from cf_estimator.bag.types import BagError, one_line, typestore


def _looks_like_bag(path: Path) -> str | None:
    """None when ``path`` may be a bag AnyReader can open, else why it is not."""
    if not path.exists():
        return "no such file or directory"
    if path.is_dir():
        if path.suffix == ".bag":
            return "a directory named *.bag cannot be read (rosbags takes .bag for ROS 1 files)"
        if not (path / "metadata.yaml").is_file():
            has_storage = any(path.glob("*.mcap")) or any(path.glob("*.db3"))
            return (
                "directory has no metadata.yaml (not a ROS 2 bag; reindex it with "
                "`ros2 bag reindex`)" if has_storage else "directory is not a ROS 2 bag "
                "(no metadata.yaml)"
            )
        return None
    if path.suffix not in (".bag", ".mcap"):  # a bare .mcap file is a ROS 2 bag (rosbags)
        return ("not a ROS 1 .bag file, a ROS 2 bag directory or .mcap file, a PX4 .ulg log or "
                "an ArduPilot .bin log")
    return None



def open_bag(path: str | os.PathLike[str], *, ulog_instance: int | None = None) -> InputBag:
    """Open a ROS 1 ``.bag``, a ROS 2 bag directory, a PX4 ``.ulg`` log
    (:mod:`cf_estimator.bag.ulog`) or an ArduPilot ``.bin`` DataFlash log
    (:mod:`cf_estimator.bag.dataflash`) — ``ulog_instance``: the instance (ulog multi_id,
    DataFlash IMU/MAG instance) to use where a topic has several; :class:`BagError` names the
    file."""
    p = Path(path)
    if p.suffix.lower() == ".ulg" and not p.is_dir():
        from cf_estimator.bag.ulog import open_ulog

        return open_ulog(p, ulog_instance)
    if p.suffix.lower() == ".bin" and not p.is_dir():
        from cf_estimator.bag.dataflash import open_dataflash

        return open_dataflash(p, ulog_instance)
    why = _looks_like_bag(p)
    if why is not None:
        raise BagError(f"{p}: {why}", 2 if not p.exists() else 1)
    from cf_estimator.bag import salvage

    # sqlite3 opens even cut short (a page missing is found while reading): its header says
    cut = salvage.truncation(p) if p.is_dir() and not any(p.glob("*.mcap")) else None
    if cut is None:
        try:
            reader = AnyReader([p], default_typestore=typestore())
            reader.open()
        except Exception as exc:  # noqa: BLE001 - AnyReaderError, ReaderError, sqlite, yaml...
            cut = salvage.truncation(p)
            if cut is None:
                kind = "ROS 1 bag" if p.suffix == ".bag" else "ROS 2 bag"
                raise BagError(f"{p}: not a readable {kind}: {one_line(exc)}") from exc
        else:
            return InputBag(p, reader)
    salvaged, note = salvage.open_truncated(p, cut)
    bag = InputBag(p, salvaged)  # type: ignore[arg-type]
    bag.truncated = True
    bag.notes.append(note)
    return bag
