"""Writes that cannot destroy: how every command of this project creates a file or a folder.

Rules (README "What is safe"):

- **Checked before anything is created.** :func:`check_outputs` refuses, with one line, an output
  that exists (unless ``force``), that is the same file as an input (compared by device and inode,
  so hard links and symlinks are caught; a target that does not exist yet is compared by its
  resolved path), that is the same file as another output of the same command, or that is a
  folder where a file is meant. A command calls it (and opens its inputs and ports) first.
- **Written beside, renamed when complete.** :func:`safe_output` hands out a temporary file in the
  target's folder; when the block ends without an exception the file is fsynced and renamed onto
  the target (``os.link`` first, which fails if the target appeared meanwhile, so even a race
  never replaces a file without ``force``), and the folder is fsynced. On an exception the
  temporary file is removed and the target is untouched.
- **Streams are written as NAME.part** (:class:`PartFile`: the live recording, event logs): a
  crash leaves ``NAME.part`` for ``replay recover``, never a half-written ``NAME``. An existing
  ``.part`` is never overwritten: it may be an earlier recording waiting to be recovered.
- **Folders** (:func:`safe_folder`, report folders): built in a temporary folder beside the target
  and renamed into place; into an existing non-empty folder only with ``force``, and then file by
  file (each one renamed onto its name; files the report does not write are left alone, an input
  inside the folder is never replaced).

The discovery command's writers use the same calls::

    check_outputs([Output("--json", args.json), Output("--report", args.report, folder=True)],
                  inputs=[args.data, args.model], force=args.force)   # before reading or fitting
    ...
    with safe_output(args.json, inputs=[...], force=args.force, label="--json") as tmp:
        tmp.write_text(json.dumps(js))
    with safe_folder(args.report, inputs=[...], force=args.force) as folder:
        (folder / "README.md").write_text(text)
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

_UMASK = os.umask(0)
os.umask(_UMASK)


@dataclass(frozen=True)
class Output:
    """One output of a command: its option (for messages), its path, and what it is."""

    label: str
    path: Path | str | None
    folder: bool = False  # a report folder rather than a file
    replaceable: bool = True  # False for a .part: never replaced, even with --force


def _stat(p: Path) -> os.stat_result | None:
    try:
        return os.stat(p)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError:
        return None


def same_file(a: str | Path, b: str | Path) -> bool:
    """True if ``a`` and ``b`` name the same file: same device and inode when both exist (hard links,
    symlinks), else the same resolved path (a target that does not exist yet but resolves to ``b``)."""
    sa, sb = _stat(Path(a)), _stat(Path(b))
    if sa is not None and sb is not None:
        return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)
    return os.path.realpath(a) == os.path.realpath(b)


def _describe(o: Output) -> str:
    return f"{o.label} {o.path}"


def check_outputs(outputs: Sequence[Output], inputs: Iterable[str | Path | None] = (), force: bool = False) -> None:
    """Refuse (ValueError, one line) any output that would destroy something; create nothing."""
    ins = [Path(i) for i in inputs if i is not None and str(i) != ""]
    outs = [o for o in outputs if o.path is not None]
    for o in outs:
        p = Path(o.path)
        for i in ins:
            if same_file(p, i):
                raise ValueError(f"{_describe(o)} is the input {i}: write the output to another file")
        if p.is_dir() and not o.folder:
            raise ValueError(f"{_describe(o)} is a folder; give a file name")
        if o.folder:
            if os.path.lexists(p) and not p.is_dir():
                raise ValueError(f"{_describe(o)} is a file; give a folder")
            if p.is_dir() and any(p.iterdir()) and not force:
                raise ValueError(f"{_describe(o)} exists and is not empty; give --force to write into it "
                                 f"(only the report's own files are replaced)")
        elif os.path.lexists(p):
            if not o.replaceable:
                raise ValueError(f"{p} exists (an earlier recording cut short?): recover it with "
                                 f"`replay recover {p} -o FIXED.mcap` or remove it")
            if not force:
                raise ValueError(f"{_describe(o)} exists; give --force to replace it")
        # where it will be written (the nearest existing folder above it, where the missing ones are made and
        # the file or folder is made beside and renamed; an existing folder's files are replaced in it too):
        # checked now, not after an analysis of minutes
        parent = p.parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise ValueError(f"{_describe(o)}: {parent} is not a folder")
        for where in (parent, p) if o.folder and p.is_dir() else (parent,):
            if not os.access(where, os.W_OK | os.X_OK):
                raise ValueError(f"{_describe(o)}: cannot write in {where} (read-only, or not yours)")
    for k, a in enumerate(outs):
        for b in outs[k + 1:]:
            if same_file(a.path, b.path):
                raise ValueError(f"{_describe(a)} and {_describe(b)} are the same file; give two names")


def _chmod_default(path: Path, mode: int = 0o666) -> None:
    os.chmod(path, mode & ~_UMASK)


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    try:
        _fsync_path(path)
    except OSError:  # some filesystems cannot fsync a folder; the rename is done either way
        pass


def commit(tmp: Path, target: Path, *, inputs: Iterable[str | Path | None] = (), force: bool = False,
           label: str = "output") -> None:
    """Rename the finished ``tmp`` onto ``target``: never onto an input, never over a file without ``force``."""
    tmp, target = Path(tmp), Path(target)
    for i in inputs:
        if i is not None and str(i) != "" and same_file(target, i):
            raise ValueError(f"{label} {target} is the input {i}: not written")
    if force:
        os.replace(tmp, target)
    else:
        try:
            os.link(tmp, target)  # atomic, and fails if the target exists: no race can clobber it
        except FileExistsError:
            raise ValueError(f"{label} {target} appeared while writing; not replaced; "
                             f"give --force to replace it") from None
        except OSError:  # a filesystem without hard links (FAT, some network shares)
            if os.path.lexists(target):
                raise ValueError(f"{label} {target} exists; not replaced") from None
            os.rename(tmp, target)
        else:
            os.unlink(tmp)
    _fsync_dir(target.parent)


@contextmanager
def safe_output(path: str | Path, inputs: Iterable[str | Path | None] = (), force: bool = False,
                label: str = "output") -> Iterator[Path]:
    """A temporary file beside ``path`` (same suffix) to write; renamed onto ``path`` when the block ends.

    Checks as :func:`check_outputs` first. On an exception in the block the temporary file is removed
    and ``path`` is untouched.
    """
    path = Path(path)
    inputs = list(inputs)
    check_outputs([Output(label, path)], inputs, force)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    tmp = Path(name)
    _chmod_default(tmp)
    try:
        yield tmp
        _fsync_path(tmp)
        commit(tmp, path, inputs=inputs, force=force, label=label)
    finally:
        if tmp.exists():
            tmp.unlink()


@contextmanager
def safe_folder(path: str | Path, inputs: Iterable[str | Path | None] = (), force: bool = False,
                label: str = "--report") -> Iterator[Path]:
    """A temporary folder beside ``path`` to fill; moved into place when the block ends.

    A new folder is renamed into place whole. Into an existing folder (empty, or any with ``force``)
    each file is renamed onto its name; files the block did not write are left alone.
    """
    path = Path(path)
    inputs = [i for i in inputs if i is not None]
    check_outputs([Output(label, path, folder=True)], inputs, force)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"))
    _chmod_default(tmp, 0o777)
    try:
        yield tmp
        files = sorted(f for f in tmp.rglob("*") if f.is_file())
        for f in files:
            _fsync_path(f)
        if not os.path.lexists(path):
            os.rename(tmp, path)
            _fsync_dir(path.parent)
            return
        for f in files:
            dest = path / f.relative_to(tmp)
            dest.parent.mkdir(parents=True, exist_ok=True)
            commit(f, dest, inputs=inputs, force=force, label=f"{label} file")
        _fsync_dir(path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


class PartFile:
    """A streamed output: written as ``NAME.part`` beside ``NAME`` and renamed by :meth:`commit`.

    A crash leaves ``NAME.part`` (recoverable), never a half-written ``NAME``. Creating the part uses
    O_EXCL: an existing ``.part`` is never overwritten.
    """

    def __init__(self, path: str | Path, inputs: Iterable[str | Path | None] = (), force: bool = False,
                 label: str = "output", mode: str = "wb", check: bool = True, resume_at: int | None = None):
        """``resume_at``: open the ``.part`` a run cut short left to append after its first ``resume_at``
        bytes (what follows them is dropped) instead of creating a new one (:meth:`resumed`)."""
        self.path = Path(path)
        self.part = part_path(self.path)
        self.inputs = list(inputs)
        self.force = force
        self.label = label
        if check:
            check_outputs([Output(label, self.path), Output(label, self.part, replaceable=False)], self.inputs, force)
        if resume_at is not None:
            fd = self._reopened(resume_at)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            try:
                fd = os.open(self.part, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            except FileExistsError:
                raise ValueError(f"{self.part} exists (an earlier recording cut short?): recover it with "
                                 f"`replay recover {self.part} -o FIXED.mcap` or remove it") from None
        self.file = os.fdopen(fd, mode)
        self.committed = False

    def _reopened(self, keep: int) -> int:
        if self.path.exists() or self.path.is_symlink():
            raise ValueError(f"{self.path} exists: a finished run is not resumed (give another name)")
        try:
            fd = os.open(self.part, os.O_WRONLY)
        except FileNotFoundError:
            raise ValueError(f"{self.part} does not exist: nothing to resume") from None
        os.ftruncate(fd, keep)
        os.lseek(fd, 0, os.SEEK_END)
        return fd

    def commit(self) -> Path:
        """Flush, fsync, close and rename onto the target; returns the final path."""
        if self.committed:
            return self.path
        if not self.file.closed:
            self.file.flush()
            os.fsync(self.file.fileno())
            self.file.close()
        try:
            commit(self.part, self.path, inputs=self.inputs, force=self.force, label=self.label)
        except ValueError as exc:
            raise ValueError(f"{exc}; the data is complete in {self.part}") from None
        self.committed = True
        return self.path

    @classmethod
    def resumed(cls, path: str | Path, keep: int, label: str = "output", mode: str = "a") -> "PartFile":
        """The ``.part`` a run cut short left beside ``path``, opened to append after its first ``keep``
        bytes (what follows them, a line cut off mid-way, is dropped). The target itself must not exist:
        a resumed part is renamed onto it as any other (:meth:`commit`)."""
        return cls(path, label=label, mode=mode, check=False, resume_at=keep)

    def abort(self) -> None:
        """Remove the ``.part`` (for a command that fails before it has recorded anything)."""
        if not self.committed:
            if not self.file.closed:
                self.file.close()
            self.part.unlink(missing_ok=True)
            self.committed = True


def part_path(path: str | Path) -> Path:
    """Where a streamed output lives until it is complete: ``NAME.part``."""
    p = Path(path)
    if not p.name or p.is_dir():  # (".", "..", "/", a folder: pathlib's "PosixPath('.') has an empty name")
        raise ValueError(f"{path} is a folder; give a file name")
    return p.with_name(p.name + ".part")
