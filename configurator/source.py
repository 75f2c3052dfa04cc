"""Where a repository's files come from: the work tree, or one git commit (no checkout).

The loader reads both the same way, so the reconciler validates exactly what a commit holds.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Protocol

from configurator.files import NotRegularFile, file_kind, read_regular
from configurator.yamlio import MAX_FILE_BYTES

ROOTS = ("configs", "models")

# What a folder entry that is not a regular file or folder is said to be, in the work tree and
# in a commit alike: the same content must get the same verdict from pre-commit and reconciler.
SYMLINK = "a symbolic link"
SUBMODULE = "a git submodule"
_ONLY_FILES = "only regular files inside the repository are read"


class SourceError(Exception):
    """The source itself could not be read (not a repository, unknown revision)."""


class Source(Protocol):
    def files(self) -> list[str]:
        """Repository-relative POSIX paths of every regular file under configs/ and models/."""
        ...

    def refused(self) -> dict[str, str]:
        """Entries under configs/ and models/ that are not read, with why (links, devices)."""
        ...

    def read(self, path: str) -> bytes:
        """The file's bytes; OSError when it cannot be read, FileTooLarge over the limit."""
        ...

    @property
    def revision(self) -> str:
        """The commit the files come from (the work tree: HEAD, marked when it differs)."""
        ...


class FileTooLarge(OSError):
    """Refused by its size, before reading it."""

    def __init__(self, size: int) -> None:
        super().__init__(
            f"file is {size:,} bytes, over the limit of {MAX_FILE_BYTES:,}; "
            "split it into smaller files"
        )
        self.size = size


def refusal(kind: str) -> str:
    """The one wording for an entry that is not read."""
    if kind == SUBMODULE:
        return f"is {kind}; {_ONLY_FILES}: commit the files themselves"
    if kind == SYMLINK:
        return f"is {kind}; {_ONLY_FILES}: replace the link with the file itself"
    return f"is {kind}, not a regular file; {_ONLY_FILES}"


def printable_path(path: str) -> str:
    """A path from the file system as text: bytes that are not UTF-8 shown as \\xNN."""
    return path.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


class WorkTreeSource:
    """Files as they are on disk: regular files only, never through a link."""

    def __init__(self, root: Path) -> None:
        self.root = root
        if not root.is_dir():
            raise SourceError(f"{root}: no such directory")
        self._revision: str | None = None
        self._refused: dict[str, str] | None = None
        self._files: list[str] | None = None

    def _scan(self) -> None:
        found: list[str] = []
        refused: dict[str, str] = {}
        for top in ROOTS:
            base = self.root / top
            try:
                mode = os.lstat(base).st_mode
            except FileNotFoundError:
                continue
            except OSError as exc:
                refused[top] = f"cannot be read ({exc.strerror})"
                continue
            if not stat.S_ISDIR(mode):
                refused[top] = refusal(file_kind(mode) or "a file") + f" ({top}/ must be a folder)"
                continue
            # Walked with a stack, not recursion: a hostile tree may nest thousands deep.
            pending = [top]
            while pending:
                rel = pending.pop()
                try:
                    entries = sorted(os.scandir(self.root / rel), key=lambda e: e.name)
                except OSError as exc:
                    refused[printable_path(rel)] = f"cannot be read ({exc.strerror})"
                    continue
                for entry in entries:
                    if entry.name.startswith("."):
                        continue
                    path = f"{rel}/{entry.name}"
                    shown = printable_path(path)
                    if shown != path:
                        refused[shown] = "has a name that is not UTF-8; rename it"
                        continue
                    try:
                        mode = entry.stat(follow_symlinks=False).st_mode
                    except OSError as exc:
                        refused[path] = f"cannot be read ({exc.strerror})"
                        continue
                    if stat.S_ISDIR(mode):
                        if os.path.lexists(os.path.join(entry.path, ".git")):
                            refused[path] = refusal(SUBMODULE)
                        else:
                            pending.append(path)
                    elif stat.S_ISREG(mode):
                        found.append(path)
                    else:
                        refused[path] = refusal(file_kind(mode) or "not a regular file")
        self._files, self._refused = sorted(found), refused

    def files(self) -> list[str]:
        if self._files is None:
            self._scan()
        assert self._files is not None
        return self._files

    def refused(self) -> dict[str, str]:
        if self._refused is None:
            self._scan()
        assert self._refused is not None
        return self._refused

    def read(self, path: str) -> bytes:
        # A file swapped for a link or a FIFO since the scan is refused, never followed.
        try:
            return read_regular(self.root / path, MAX_FILE_BYTES)
        except NotRegularFile:
            size = os.stat(self.root / path, follow_symlinks=False).st_size
            if size > MAX_FILE_BYTES:
                raise FileTooLarge(size) from None
            raise

    @property
    def revision(self) -> str:
        if self._revision is None:
            self._revision = _worktree_revision(self.root)
        return self._revision


def _worktree_revision(root: Path) -> str:
    """HEAD's commit, with `+dirty` when configs/ or models/ differ from it."""
    try:
        import git  # GitPython: server side only, imported when needed
    except ImportError:
        return "worktree"
    try:
        repo = git.Repo(root, search_parent_directories=True)
        head = repo.head.commit.hexsha
    except (git.InvalidGitRepositoryError, git.NoSuchPathError, ValueError):
        return "worktree"
    try:
        paths = [os.path.relpath(root / r, repo.working_tree_dir or root) for r in ROOTS]
        dirty = bool(repo.git.status("--porcelain", "--", *paths))
    finally:
        repo.close()
    return f"{head}+dirty" if dirty else head


_LINK_MODE = 0o120000
_GITLINK_MODE = 0o160000


class GitSource:
    """Files as one commit holds them, read through GitPython without touching the work tree."""

    def __init__(self, root: Path, rev: str) -> None:
        try:
            import git
        except ImportError as exc:  # pragma: no cover - the server extra installs it
            raise SourceError(
                "reading a commit needs GitPython: pip install 'robotconf[server]'"
            ) from exc
        if not rev or rev.startswith("-") or any(c in rev for c in "\0\n\r"):
            raise SourceError(f"{rev!r} is not a revision (a commit, branch or tag name)")
        try:
            self._repo = git.Repo(root, search_parent_directories=True)
        except (git.InvalidGitRepositoryError, git.NoSuchPathError):
            raise SourceError(f"{root}: not a git repository") from None
        try:
            commit = self._repo.commit(rev)
        except Exception:  # BadName, ValueError, GitCommandError, a tag of a tree, a bad object
            self._repo.close()
            raise SourceError(f"{rev!r}: no such revision in {root}") from None
        self._revision = commit.hexsha
        self._blobs: dict[str, Any] = {}
        self._refused: dict[str, str] = {}
        try:
            self._index(root, rev, commit)
        except SourceError:
            self._repo.close()
            raise
        except Exception as exc:  # a corrupt or missing object (a shallow clone's edge)
            self._repo.close()
            raise SourceError(f"{rev!r} cannot be read in {root}: {exc}") from None

    def _index(self, root: Path, rev: str, commit: Any) -> None:
        # The repository may live in a subfolder of the git work tree.
        prefix = Path(
            os.path.relpath(root.resolve(), Path(self._repo.working_tree_dir or root).resolve())
        )
        base = commit.tree
        if prefix.as_posix() != ".":
            try:
                base = base / prefix.as_posix()
            except KeyError:
                raise SourceError(f"{rev!r} has no folder {prefix.as_posix()}") from None
        for top in ROOTS:
            try:
                tree = base / top
            except KeyError:
                continue
            if tree.type != "tree":
                kind = SYMLINK if tree.mode == _LINK_MODE else SUBMODULE
                if tree.type == "blob" and tree.mode != _LINK_MODE:
                    kind = "a file"
                self._refused[top] = refusal(kind) + f" ({top}/ must be a folder)"
                continue
            for item, rel in _entries(tree, top):
                if Path(rel).name.startswith("."):
                    continue
                if item.type == "blob" and item.mode != _LINK_MODE:
                    self._blobs[rel] = item
                else:
                    self._refused[rel] = refusal(SYMLINK if item.mode == _LINK_MODE else SUBMODULE)

    def files(self) -> list[str]:
        return sorted(self._blobs)

    def refused(self) -> dict[str, str]:
        return self._refused

    def read(self, path: str) -> bytes:
        blob = self._blobs[path]
        if blob.size > MAX_FILE_BYTES:
            raise FileTooLarge(blob.size)
        data: bytes = blob.data_stream.read()
        return data

    @property
    def revision(self) -> str:
        return self._revision

    def close(self) -> None:
        self._repo.close()


def _entries(tree: Any, top: str) -> Iterator[tuple[Any, str]]:
    """Every blob, link and submodule below `tree`, with its repository path; the contents of
    hidden folders are skipped as the work tree's are, links and submodules not entered."""
    pending = [(tree, top)]
    while pending:  # a stack, not recursion: a hostile commit may nest thousands deep
        current, where = pending.pop()
        for item in current:
            name = item.path.rsplit("/", 1)[-1]  # a submodule has no `name` until configured
            rel = f"{where}/{name}"
            if item.type == "tree":
                if not name.startswith("."):
                    pending.append((item, rel))
            else:
                yield item, rel


def open_source(root: Path, rev: str | None) -> Source:
    return WorkTreeSource(root) if rev is None else GitSource(root, rev)
