"""Where a repository's files come from: the work tree, or one git commit (no checkout).

The loader reads both the same way, so the reconciler validates exactly what a commit holds.
"""

from __future__ import annotations

import os
import re
import stat
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Protocol

from robotconf.contract.files import NotRegularFile, file_kind, read_regular
from robotconf.contract.yamlio import MAX_FILE_BYTES

if TYPE_CHECKING:
    import subprocess

ROOTS = ("configs", "models")
# The one file read outside ROOTS: the lab's rule configuration (configurator/ruleconfig.py).
RULE_CONFIGURATION = ".robotconf.yaml"
# Listed too, so that the loader says the file is misnamed (RC105) rather than unread in silence.
_ROOT_FILES = (RULE_CONFIGURATION, ".robotconf.yml")

# What a folder entry that is not a regular file or folder is said to be, in the work tree and
# in a commit alike: the same content must get the same verdict from pre-commit and reconciler.
SYMLINK = "a symbolic link"
SUBMODULE = "a git submodule"
_ONLY_FILES = "only regular files inside the repository are read"


class SourceError(Exception):
    """The source itself could not be read (not a repository, unknown revision)."""


class Source(Protocol):
    def files(self) -> list[str]:
        """Repository-relative POSIX paths of every regular file under configs/ and models/,
        and of RULE_CONFIGURATION (or a misspelling of it) when the root holds it."""
        ...

    def refused(self) -> dict[str, str]:
        """Entries under configs/ and models/ that are not read, with why (links, devices)."""
        ...

    def read(self, path: str) -> bytes:
        """The file's bytes; OSError when it cannot be read, FileTooLarge over the limit."""
        ...

    def read_each(self, paths: Sequence[str]) -> Iterator[tuple[str, bytes | OSError]]:
        """Each file's bytes, or the OSError `read` would raise, in the order given: many files
        in one pass."""
        ...

    def blob_id(self, path: str) -> str | None:
        """The file's git blob id when the source knows it without reading the file."""
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
        for name in _ROOT_FILES:
            self._scan_root_file(name, found, refused)
        self._files, self._refused = sorted(found), refused

    def _scan_root_file(self, name: str, found: list[str], refused: dict[str, str]) -> None:
        try:
            mode = os.lstat(self.root / name).st_mode
        except FileNotFoundError:
            return
        except OSError as exc:
            refused[name] = f"cannot be read ({exc.strerror})"
            return
        if stat.S_ISREG(mode):
            found.append(name)
        else:
            refused[name] = refusal(file_kind(mode) or "a folder")

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

    def read_each(self, paths: Sequence[str]) -> Iterator[tuple[str, bytes | OSError]]:
        for path in paths:
            try:
                yield path, self.read(path)
            except OSError as exc:
                yield path, exc

    def blob_id(self, path: str) -> str | None:
        return None

    @property
    def revision(self) -> str:
        if self._revision is None:
            self._revision = _worktree_revision(self.root)
        return self._revision


def _worktree_revision(root: Path) -> str:
    """HEAD's commit, with `+dirty` when configs/, models/ or .robotconf.yaml differ from it."""
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
        paths = [
            os.path.relpath(root / r, repo.working_tree_dir or root)
            for r in (*ROOTS, RULE_CONFIGURATION)
        ]
        dirty = bool(repo.git.status("--porcelain", "--", *paths))
    finally:
        repo.close()
    return f"{head}+dirty" if dirty else head


_LINK_MODE = "120000"
_GITLINK_MODE = "160000"
_REGULAR_MODES = ("100644", "100755")
_OBJECT_ID = re.compile(r"^[0-9a-f]{40}(?:[0-9a-f]{24})?$")  # SHA-1 or SHA-256 repositories
_HEADER_LIMIT = 200  # `<id> blob <size>` or `<id> missing`


class GitSource:
    """Files as one commit holds them, without touching the work tree: the listing from one
    `git ls-tree -r`, the contents from one `git cat-file --batch` pass (never a process per
    file, never a checkout)."""

    def __init__(self, root: Path, rev: str) -> None:
        if not rev or rev.startswith("-") or any(c in rev for c in "\0\n\r"):
            raise SourceError(f"{rev!r} is not a revision (a commit, branch or tag name)")
        self._root = root
        if not root.is_dir():
            raise SourceError(f"{root}: no such directory")
        # One process for both: the folder of the git work tree the repository is in, and
        # the commit (a process costs a few milliseconds; the reconciler reads every commit).
        found = _git(root, "rev-parse", "--show-prefix", "--verify", "--quiet", f"{rev}^{{commit}}")
        # The prefix's line, then the commit's (the prefix is a folder: it may hold a newline).
        prefix, _, commit = found.stdout.decode("utf-8", "surrogateescape")[:-1].rpartition("\n")
        if found.returncode != 0 or not _OBJECT_ID.match(commit):
            if _git(root, "rev-parse", "--show-prefix").returncode != 0:
                raise SourceError(f"{root}: not a git repository")
            raise SourceError(f"{rev!r}: no such revision in {root}")
        # The repository may live in a subfolder of the git work tree.
        prefix = prefix.strip().rstrip("/")
        self._revision = commit
        self._blobs: dict[str, str] = {}  # path -> blob id
        self._refused: dict[str, str] = {}
        tree = f"{commit}:{prefix}" if prefix else commit
        # --full-tree: the paths given are in `tree`, whatever folder git runs in. No sizes
        # (-l): git would open every blob for its size (loose objects: 70 ms for 1,500 files),
        # while an incremental build reads only the blobs that changed; a blob's size comes
        # with its content (`read_each`).
        listing = _git(root, "ls-tree", "-r", "-z", "--full-tree", tree, "--", *ROOTS, *_ROOT_FILES)
        if listing.returncode != 0:
            if prefix:
                raise SourceError(f"{rev!r} has no folder {prefix}")
            detail = _first_line(listing.stderr)
            raise SourceError(f"{rev!r} cannot be read in {root}: {detail}")
        self._index(listing.stdout)

    def _index(self, listing: bytes) -> None:
        for record in listing.split(b"\0"):
            if not record:
                continue
            meta, _, raw_path = record.partition(b"\t")
            mode, kind, object_id = meta.decode("ascii", "replace").split()
            path = raw_path.decode("utf-8", "surrogateescape")
            parts = path.split("/")
            if any(part.startswith(".") for part in parts[1:]):
                continue  # hidden files and the contents of hidden folders, as in the work tree
            shown = printable_path(path)
            if shown != path:
                self._refused[shown] = "has a name that is not UTF-8; rename it"
            elif parts[0] in _ROOT_FILES and len(parts) > 1:
                self._refused[parts[0]] = refusal("a folder")
            elif path in _ROOT_FILES and kind == "blob" and mode in _REGULAR_MODES:
                self._blobs[path] = object_id
            elif path in _ROOT_FILES:
                self._refused[path] = refusal(SYMLINK if mode == _LINK_MODE else SUBMODULE)
            elif len(parts) == 1:  # configs or models itself is no folder
                what = {_LINK_MODE: SYMLINK, _GITLINK_MODE: SUBMODULE}.get(mode, "a file")
                self._refused[path] = refusal(what) + f" ({path}/ must be a folder)"
            elif kind == "blob" and mode in _REGULAR_MODES:
                self._blobs[path] = object_id
            else:
                self._refused[path] = refusal(SYMLINK if mode == _LINK_MODE else SUBMODULE)

    def files(self) -> list[str]:
        return sorted(self._blobs)

    def refused(self) -> dict[str, str]:
        return self._refused

    def blob_id(self, path: str) -> str | None:
        return self._blobs[path]

    def read(self, path: str) -> bytes:
        for _, data in self.read_each([path]):
            if isinstance(data, OSError):
                raise data
            return data
        raise AssertionError("read_each yields once a path")  # pragma: no cover

    def read_each(self, paths: Sequence[str]) -> Iterator[tuple[str, bytes | OSError]]:
        """Each file's bytes (or why not) in the order given, from one `git cat-file --batch`
        process. A file over the size limit is refused by the size git announces, unread: the
        process is stopped there and another one answers for the files after it."""
        done = 0
        while done < len(paths):
            proc = self._cat_file([self._blobs[path] for path in paths[done:]])
            assert proc.stdout is not None
            try:
                while done < len(paths):
                    path = paths[done]
                    done += 1
                    data = self._answer(proc.stdout, path, self._blobs[path])
                    yield path, data
                    if isinstance(data, FileTooLarge):
                        break  # its content is next in the stream: never read
            finally:
                proc.stdout.close()
                proc.kill()
                proc.wait()

    def _cat_file(self, object_ids: list[str]) -> subprocess.Popen[bytes]:
        with tempfile.TemporaryFile() as ids:
            # From a file, not a pipe: git answers as it reads, and a pipe both ways could fill
            # up in both directions at once.
            ids.write("".join(f"{object_id}\n" for object_id in object_ids).encode("ascii"))
            ids.seek(0)
            import subprocess  # a commit's files only: the work tree starts no process

            try:
                return subprocess.Popen(
                    ["git", "cat-file", "--batch"],
                    cwd=self._root,
                    stdin=ids,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.DEVNULL,
                    env=_GIT_ENV,
                )
            except OSError as exc:
                raise SourceError(f"cannot run git: {exc.strerror or exc}") from None

    def _answer(self, stream: IO[bytes], path: str, object_id: str) -> bytes | FileTooLarge:
        header = stream.readline(_HEADER_LIMIT).decode("ascii", "replace").split()
        if header[:1] != [object_id] or len(header) < 2:
            raise SourceError(f"{self._revision}: git did not answer for {path}")
        if header[1] != "blob" or len(header) != 3 or not header[2].isdigit():
            raise SourceError(_missing(self._revision, path, object_id))
        size = int(header[2])
        if size > MAX_FILE_BYTES:
            return FileTooLarge(size)
        data = stream.read(size)
        if len(data) != size or stream.read(1) != b"\n":
            raise SourceError(f"{self._revision}: git's answer for {path} was cut short")
        return data

    @property
    def revision(self) -> str:
        return self._revision

    def close(self) -> None:
        return None


# No pager, no prompt, no locks taken for reading; pathspecs taken literally.
_GIT_ENV = {
    **os.environ,
    "GIT_PAGER": "cat",
    "GIT_TERMINAL_PROMPT": "0",
    "GIT_OPTIONAL_LOCKS": "0",
    "GIT_LITERAL_PATHSPECS": "1",
}


def _git(root: Path, *args: str) -> subprocess.CompletedProcess[bytes]:
    import subprocess  # see GitSource.read_each

    try:
        return subprocess.run(
            ["git", *args], cwd=root, capture_output=True, env=_GIT_ENV, timeout=300
        )
    except OSError as exc:
        raise SourceError(f"cannot run git: {exc.strerror or exc}") from None
    except subprocess.TimeoutExpired:
        raise SourceError(f"git {args[0]} took over 300 s in {root}") from None


def _missing(revision: str, path: str, object_id: str) -> str:
    return (
        f"{revision}: {path} (object {object_id}) is missing from the repository "
        "(a shallow or damaged clone?)"
    )


def _first_line(stderr: bytes) -> str:
    lines = stderr.decode("utf-8", "replace").strip().splitlines()
    return lines[0] if lines else "git failed"


def open_source(root: Path, rev: str | None) -> Source:
    return WorkTreeSource(root) if rev is None else GitSource(root, rev)


class OverlaySource:
    """Another source with some files added or replaced: a file a command would write,
    validated with the repository before it is written."""

    def __init__(self, base: Source, files: dict[str, bytes]) -> None:
        self._base = base
        self._files = dict(files)

    def files(self) -> list[str]:
        return sorted({*self._base.files(), *self._files})

    def refused(self) -> dict[str, str]:
        return {p: why for p, why in self._base.refused().items() if p not in self._files}

    def read(self, path: str) -> bytes:
        return self._files[path] if path in self._files else self._base.read(path)

    def read_each(self, paths: Sequence[str]) -> Iterator[tuple[str, bytes | OSError]]:
        theirs = iter(self._base.read_each([p for p in paths if p not in self._files]))
        for path in paths:
            yield (path, self._files[path]) if path in self._files else next(theirs)

    def blob_id(self, path: str) -> str | None:
        return None if path in self._files else self._base.blob_id(path)

    @property
    def revision(self) -> str:
        return self._base.revision
