"""Where a repository's files come from: the work tree, or one git commit (no checkout).

The loader reads both the same way, so the reconciler validates exactly what a commit holds.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Protocol

ROOTS = ("configs", "models")


class SourceError(Exception):
    """The source itself could not be read (not a repository, unknown revision)."""


class Source(Protocol):
    def files(self) -> list[str]:
        """Repository-relative POSIX paths of every file under configs/ and models/."""
        ...

    def read(self, path: str) -> bytes: ...

    @property
    def revision(self) -> str:
        """The commit the files come from (the work tree: HEAD, marked when it differs)."""
        ...


class WorkTreeSource:
    """Files as they are on disk."""

    def __init__(self, root: Path) -> None:
        self.root = root
        if not root.is_dir():
            raise SourceError(f"{root}: no such directory")
        self._revision: str | None = None

    def files(self) -> list[str]:
        found: list[str] = []
        for top in ROOTS:
            base = self.root / top
            for dirpath, dirnames, filenames in os.walk(base):
                dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
                rel = Path(dirpath).relative_to(self.root).as_posix()
                found.extend(f"{rel}/{name}" for name in filenames if not name.startswith("."))
        return sorted(found)

    def read(self, path: str) -> bytes:
        return (self.root / path).read_bytes()

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


class GitSource:
    """Files as one commit holds them, read through GitPython without touching the work tree."""

    def __init__(self, root: Path, rev: str) -> None:
        try:
            import git
        except ImportError as exc:  # pragma: no cover - the server extra installs it
            raise SourceError(
                "reading a commit needs GitPython: pip install 'robotconf[server]'"
            ) from exc
        try:
            self._repo = git.Repo(root, search_parent_directories=True)
        except (git.InvalidGitRepositoryError, git.NoSuchPathError):
            raise SourceError(f"{root}: not a git repository") from None
        try:
            commit = self._repo.commit(rev)
        except (git.BadName, ValueError, git.GitCommandError):
            raise SourceError(f"{rev!r}: no such revision in {root}") from None
        self._revision = commit.hexsha
        self._blobs: dict[str, Any] = {}
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
            for item in _blobs(tree):
                rel = f"{top}/{Path(item.path).relative_to(Path(tree.path)).as_posix()}"
                if not Path(rel).name.startswith("."):
                    self._blobs[rel] = item

    def files(self) -> list[str]:
        return sorted(self._blobs)

    def read(self, path: str) -> bytes:
        data: bytes = self._blobs[path].data_stream.read()
        return data

    @property
    def revision(self) -> str:
        return self._revision

    def close(self) -> None:
        self._repo.close()


def _blobs(tree: Any) -> Iterator[Any]:
    for item in tree.traverse():
        if item.type == "blob":
            yield item


def open_source(root: Path, rev: str | None) -> Source:
    return GitSource(root, rev) if rev else WorkTreeSource(root)
