"""Output sets: the files of a render are written together, or not at all.

A render writes image.exr, preview.png and report.json into one folder. :class:`OutputSet` makes them
a set:

- :meth:`OutputSet.open`, before the first ray: the folder is checked (a folder, or one that can be
  made under folders; writable; its image.exr, preview.png and report.json, where they exist, are
  files) and locked, so that a second render into the same folder is refused instead of mixing its
  files with this one's. A folder that cannot take the outputs raises :class:`OutputFolderError`
  before any work is done.
- :meth:`OutputSet.commit` (or :meth:`OutputSet.staging`, file by file as each is ready), after the
  render: every file is written into a hidden staging folder inside the target, read back and checked
  by its own check (the EXR's header and its first and last rows equal to what was meant, the PNG's
  pixels, the JSON parses), and only then moved into place, one rename each; should a rename fail,
  the files already moved are put back. Any failure leaves the older set as it was and raises
  :class:`OutputWriteError` (a full disk, for instance, which OpenEXR does not always report: the
  read-back finds the short file).
- :meth:`OutputSet.close` releases the lock and removes a folder that :meth:`open` created and that
  is still empty (a render that failed or was aborted leaves nothing behind).

The lock is ``flock`` on the folder itself (POSIX); where it does not exist (Windows) there is no
lock, and the staging still keeps every set whole.
"""

from __future__ import annotations

import os
import shutil
import uuid
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import TracerError, one_line, printable
from ..core.imageio import read_codes, write_png

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

#: Prefix of the staging folders inside a target folder (left over only by a killed process; removed
#: by the next render that holds the lock).
STAGING_PREFIX = ".hud-staging-"

_writing = False
_committed = 0


def committed() -> int:
    """How many output sets this process has moved into place: a second stop signal that comes after a
    command's set was moved there aborts what follows (the analysis), not the set, which is whole."""
    return _committed


def writing() -> bool:
    """Whether an :meth:`OutputSet.commit` is under way in this process: an interrupt handler must
    then let it finish (it takes a fraction of a second) rather than raise into the middle of the
    swap, which would leave a mixed set, or of a C library's write, which prints its own error."""
    return _writing


class OutputError(TracerError):
    """An output folder or file problem; ``path`` is the folder or file at fault."""

    def __init__(self, path, message: str):
        self.path = printable(path)
        self.message = message = one_line(message)
        super().__init__(f"{self.path}: {message}")


class OutputFolderError(OutputError):
    """The output folder cannot take a render's outputs (found before the render starts)."""


class OutputWriteError(OutputError):
    """Writing the outputs failed; the folder keeps its earlier outputs."""


@dataclass
class OutputFile:
    """One file of a set: ``write(path)`` writes it, ``check(path)`` reads it back and raises (any
    exception) if it is not what was meant."""

    name: str
    write: Callable[[Path], None]
    check: Callable[[Path], None]


def _write_and_check(f: OutputFile, path: Path) -> tuple[str | None, Exception | None]:
    """Write ``f`` at ``path`` and read it back: ("write", the OSError) if writing failed, ("check",
    the exception) if the read-back did, else (None, None)."""
    try:
        f.write(path)
    except OSError as e:
        return "write", e
    try:
        f.check(path)
    except Exception as e:  # noqa: BLE001 - any failure of the read-back means a bad file
        return "check", e
    return None, None


class OutputSet:
    """The output folder of one render (see the module docstring)."""

    def __init__(self, folder, names: tuple[str, ...], scene_root=None):
        """``scene_root``: the folder of the scene rendered, which the output folder must not be nor lie
        in (the outputs would mix with, or overwrite, the scene's own files, and travel with the folder
        wherever it is copied or zipped)."""
        #: An empty name would be Path("."), the working directory: refused by :meth:`open`.
        self._given = folder
        self.folder = Path(folder)
        self.scene_root = None if scene_root is None else Path(scene_root)
        self.names = tuple(names)
        self._fd: int | None = None
        self._created: list[Path] = []

    # -- before the render -----------------------------------------------------------------------
    def open(self) -> OutputSet:
        """Check and lock the folder (creating it, and missing parents, if needed)."""
        folder = self.folder
        if isinstance(self._given, str) and not self._given.strip():
            what = "an empty folder name" if not self._given else "a folder name of blanks only"
            raise OutputFolderError(repr(self._given), f"{what}; give the output folder (\".\" for this one)")
        if "\0" in str(folder):
            raise OutputFolderError(folder, "a folder name must not contain a NUL character")
        try:
            return self._open()
        except OSError as e:  # the name itself: too long, a component not a folder, a loop of links
            raise OutputFolderError(folder, f"cannot be used ({e.strerror or e})") from None

    def _open(self) -> OutputSet:
        folder = self.folder
        if self.scene_root is not None:
            root = Path(os.path.realpath(self.scene_root))
            if Path(os.path.realpath(folder)).is_relative_to(root):
                raise OutputFolderError(folder, f"lies in the scene folder {printable(root)}; the outputs would mix "
                                                "with the scene's own files: choose a folder outside it")
        if folder.exists() and not folder.is_dir():
            raise OutputFolderError(folder, "exists and is not a folder")
        missing = []
        p = folder
        while not p.exists():
            missing.append(p)
            if p.parent == p:
                break
            p = p.parent
        if p.exists() and not p.is_dir():
            raise OutputFolderError(folder, f"cannot be made: {p} is not a folder")
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise OutputFolderError(folder, f"cannot be made ({e.strerror or e})") from None
        self._created = list(reversed(missing))  # outermost first
        try:
            self._lock()
            self._remove_stale_staging()
            for name in self.names:
                target = folder / name
                if target.exists() and (target.is_dir() or not target.is_file()):
                    raise OutputFolderError(target, "exists and is not a file; the render would write a file there")
            probe = folder / f"{STAGING_PREFIX}probe-{uuid.uuid4().hex}"
            try:
                probe.mkdir()
                (probe / "w").write_bytes(b"0")
            except OSError as e:
                raise OutputFolderError(folder, f"is not writable ({e.strerror or e})") from None
            finally:
                shutil.rmtree(probe, ignore_errors=True)
        except BaseException:
            self.close()
            raise
        return self

    def _lock(self):
        """flock the folder. Several renders may create it at once, and one that then fails removes the
        folder it made (only while it holds the lock): a lock on a folder that is no longer the one at
        the path is dropped and taken again on the new one."""
        if fcntl is None:
            return
        for _ in range(10):
            try:
                fd = os.open(self.folder, os.O_RDONLY)
            except FileNotFoundError:
                self.folder.mkdir(parents=True, exist_ok=True)
                continue
            except OSError as e:
                raise OutputFolderError(self.folder, f"cannot be opened ({e.strerror or e})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                raise OutputFolderError(self.folder, "another render is writing into this folder; choose another "
                                                     "--out or wait for it to finish") from None
            try:
                current = os.path.samestat(os.fstat(fd), os.stat(self.folder))
            except FileNotFoundError:
                current = False
            if current:
                self._fd = fd
                return
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
            try:
                self.folder.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise OutputFolderError(self.folder, f"cannot be made ({e.strerror or e})") from None
        raise OutputFolderError(self.folder, "was removed again and again while being locked; choose another --out")

    def _remove_stale_staging(self):
        for p in self.folder.glob(f"{STAGING_PREFIX}*"):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)

    # -- after the render ------------------------------------------------------------------------
    def commit(self, files: list[OutputFile]):
        """Write, check and move ``files`` into the folder as one set (see the module docstring)."""
        with self.staging() as stage:
            for f in files:
                stage.add(f)
            stage.finish()

    def staging(self) -> Staging:
        """A set written file by file as each is ready (:class:`Staging`); :meth:`commit` at once."""
        return Staging(self)

    def _swap(self, staging: Path, names: list[str]):
        """Move the staged files onto the targets; on failure put back what was there."""
        global _committed
        backups: dict[str, Path | None] = {}
        try:
            for name in names:
                target = self.folder / name
                backup = None
                if target.exists():
                    backup = staging / f".old-{name}"
                    try:
                        os.link(target, backup)  # the old file stays where it is until the replace
                    except OSError:
                        shutil.copy2(target, backup)
                backups[name] = backup
                os.replace(staging / name, target)
        except OSError as e:
            for name, backup in backups.items():
                target = self.folder / name
                try:
                    if backup is not None:
                        os.replace(backup, target)
                    else:
                        target.unlink(missing_ok=True)
                except OSError:
                    pass
            raise OutputWriteError(self.folder, f"moving the outputs into place failed ({e}); the earlier outputs "
                                                "are kept") from None
        _committed += 1

    # -- always ----------------------------------------------------------------------------------
    def close(self):
        """Remove the folders :meth:`open` made if they hold nothing, then release the lock. Only a
        render that held the lock removes anything: one refused by the lock leaves the folder to the
        render that holds it (it may have made it at the same moment)."""
        held = self._fd is not None or fcntl is None
        if held:
            for p in reversed(self._created):  # innermost first
                try:
                    p.rmdir()
                except OSError:
                    break
        self._created = []
        if self._fd is not None:
            try:
                fcntl.flock(self._fd, fcntl.LOCK_UN)
            finally:
                os.close(self._fd)
                self._fd = None

    def keep(self):
        """The render wrote its set: the folders made by :meth:`open` stay."""
        self._created = []

    def __enter__(self) -> OutputSet:
        return self.open()

    def __exit__(self, *exc):
        self.close()


class Staging:
    """A set of files being written (:meth:`OutputSet.staging`): each file :meth:`add` is given is
    written into a hidden staging folder inside the target and read back in a thread of its own at
    once (the image libraries and numpy let go of the interpreter, so a 4K render's EXR is written
    while its preview and report are still computed, and a set takes the time of its largest file);
    :meth:`finish` waits for them, raises :class:`OutputWriteError` for the first that failed, and
    moves the whole set into place. Leaving the ``with`` block waits for writes still running and
    removes the staging folder: a set that did not finish leaves nothing behind."""

    def __init__(self, outputs: OutputSet):
        global _writing
        self.outputs = outputs
        self.folder = outputs.folder / f"{STAGING_PREFIX}{uuid.uuid4().hex}"
        try:
            self.folder.mkdir()
        except OSError as e:
            raise OutputWriteError(outputs.folder, f"writing the outputs failed ({e}); the earlier outputs are "
                                                   "kept") from None
        _writing = True
        self._pool = ThreadPoolExecutor(max_workers=len(outputs.names))
        self._added: list[tuple[OutputFile, Future]] = []

    def add(self, f: OutputFile):
        """Start writing and reading back ``f``, one of the set's names not yet added."""
        if f.name not in self.outputs.names or f.name in (g.name for g, _ in self._added):
            raise ValueError(f"an output set is {self.outputs.names}; {f.name!r} is not one of them or was added")
        self._added.append((f, self._pool.submit(_write_and_check, f, self.folder / f.name)))

    def finish(self):
        """Wait for every file, then move the set into place (:class:`OutputWriteError` if one failed)."""
        names = [f.name for f, _ in self._added]
        if sorted(names) != sorted(self.outputs.names):
            raise ValueError(f"an output set is {self.outputs.names}, got {names}")
        outcomes = [(f, future.result()) for f, future in self._added]
        for _, (stage, e) in outcomes:
            if stage == "write":
                raise OutputWriteError(self.outputs.folder, f"writing the outputs failed ({e}); the earlier outputs "
                                                            "are kept")
        for f, (stage, e) in outcomes:
            if stage == "check":
                raise OutputWriteError(self.outputs.folder / f.name, f"the written file does not read back ({e}); "
                                       "the disk may be full; the earlier outputs are kept")
        self.outputs._swap(self.folder, names)

    def __enter__(self) -> Staging:
        return self

    def __exit__(self, *exc):
        global _writing
        self._pool.shutdown(wait=True)
        shutil.rmtree(self.folder, ignore_errors=True)
        _writing = False


def replace_folder(staging: Path, target: Path) -> Path | None:
    """Put the complete folder ``staging`` in the place of ``target`` (absent, empty, or an earlier
    set of files), the folder-level counterpart of :meth:`OutputSet.commit` (``hud-trace export``
    and the add-on's export). An existing target is renamed aside to a hidden backup beside it and
    renamed back if ``staging`` cannot take its place; once it has, the backup is removed. Returns
    the backup's path if that last removal failed (the new folder stands; the caller says so), else
    None."""
    if not target.exists():
        os.rename(staging, target)
        return None
    backup = target.parent / f".{target.name}.backup-{uuid.uuid4().hex}"
    os.rename(target, backup)
    try:
        os.rename(staging, target)
    except BaseException:
        os.rename(backup, target)
        raise
    try:
        shutil.rmtree(backup)
    except OSError:
        return backup
    return None


def write_as_set(path, write, check) -> None:
    """Write one file as a set of one (:class:`tracer.products.outputs.OutputSet`): its folder is checked and
    locked, the file written beside it in a staging folder, read back by ``check(staged_path)``
    and only then moved onto ``path``. Raises :class:`~tracer.products.outputs.OutputFolderError` when the
    folder cannot take it, :class:`~tracer.products.outputs.OutputWriteError` when writing fails (``path``
    then keeps what it held)."""
    path = Path(path)
    outputs = OutputSet(path.parent, (path.name,)).open()
    try:
        outputs.commit([OutputFile(path.name, write, check)])
        outputs.keep()
    finally:
        outputs.close()


def png_file(name: str, rgb: np.ndarray) -> OutputFile:
    """An 8-bit PNG of ``rgb`` as a file of a set, checked by reading its pixels back."""
    def check(p):
        back = read_codes(p)
        if back.shape != rgb.shape or not np.array_equal(back, rgb):
            raise ValueError("the pixels read back differ from those written")

    return OutputFile(name, lambda p: write_png(p, rgb), check)
