"""Source step: which commit is the branch's head, and when it may have moved (git via GitPython).

A local repository is watched (its refs, packed-refs and HEAD, with watchfiles); a remote is
fetched into a bare cache clone. Either way only commits are read, never a work tree.
"""

from __future__ import annotations

import hashlib
import logging
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from robotconf.configurator.source import SourceError
from robotconf.contract.wire import redact_url

log = logging.getLogger("robotconf.reconciler")


class BranchSource(Protocol):
    """Where the desired state comes from."""

    branch: str

    @property
    def root(self) -> Path:
        """The repository folder to read commits from (given to `configurator.workspace.check`)."""
        ...

    @property
    def description(self) -> str:
        """Shown in the reconciler status: a path or a URL without credentials."""
        ...

    def head(self) -> str:
        """The branch's head commit; raises SourceError."""
        ...

    def refresh(self) -> None:
        """Brings the source up to date (a fetch); raises SourceError."""
        ...

    def watch(self, wake: Callable[[], None], stop: threading.Event) -> bool:
        """Calls `wake` soon after the head may have moved; False when it cannot watch."""
        ...


def _git() -> Any:
    try:
        import git
    except ImportError as exc:  # pragma: no cover - the server extra installs it
        raise SourceError(
            "the reconciler needs GitPython: pip install 'robotconf[server]'"
        ) from exc
    return git


def open_repo(path: Path) -> Any:
    git = _git()
    try:
        return git.Repo(path, search_parent_directories=True)
    except (git.InvalidGitRepositoryError, git.NoSuchPathError):
        raise SourceError(
            f"{path}: not a git repository; the reconciler applies commits only "
            "(git init && git add configs models && git commit)"
        ) from None


def _resolve(repo: Any, branch: str, where: str) -> str:
    git = _git()
    try:
        sha: str = repo.commit(f"refs/heads/{branch}").hexsha
    except (git.BadName, ValueError, git.GitCommandError):
        known = sorted(h.name for h in repo.heads)
        listing = ", ".join(known[:10]) if known else "none"
        raise SourceError(
            f"branch '{branch}' does not exist in {where} (branches: {listing})"
        ) from None
    return sha


class LocalBranch:
    """A branch of a repository on this machine."""

    def __init__(self, root: Path, branch: str) -> None:
        self.branch = branch
        self._root = root.absolute()
        repo = open_repo(self._root)
        try:
            self._git_dir = Path(repo.common_dir).absolute()
            self._head_dir = Path(repo.git_dir).absolute()
        finally:
            repo.close()

    @property
    def root(self) -> Path:
        return self._root

    @property
    def description(self) -> str:
        return str(self._root)

    def head(self) -> str:
        repo = open_repo(self._root)  # fresh each time: GitPython may cache packed refs
        try:
            return _resolve(repo, self.branch, str(self._root))
        finally:
            repo.close()

    def refresh(self) -> None:
        return None

    def watch(self, wake: Callable[[], None], stop: threading.Event) -> bool:
        try:
            import watchfiles
        except ImportError:
            log.warning("watchfiles is not installed: new commits are noticed by polling only")
            return False
        paths = {self._git_dir, self._head_dir}
        wanted_refs = (self._git_dir / "refs" / "heads").as_posix() + "/"

        def relevant(change: Any, path: str) -> bool:
            posix = Path(path).as_posix()
            name = os.path.basename(posix)
            return posix.startswith(wanted_refs) or name in ("packed-refs", "HEAD")

        def run() -> None:
            try:
                # Small debounce: git writes a ref with lock + rename, a burst of a few events.
                for _ in watchfiles.watch(
                    *sorted(paths),
                    watch_filter=relevant,
                    debounce=30,
                    step=10,
                    stop_event=stop,
                    raise_interrupt=False,
                    rust_timeout=1000,
                ):
                    wake()
            except Exception as exc:  # the periodic resync still runs
                log.warning("stopped watching %s (%s); relying on polling", self._git_dir, exc)

        threading.Thread(target=run, name="robotconf-ref-watch", daemon=True).start()
        return True


def redact(url: str) -> str:
    """The URL without user name or password, for logs and the retained status."""
    return redact_url(url)


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "robotconf" / "remotes"


class RemoteBranch:
    """A branch of a remote repository, fetched into a bare cache clone."""

    def __init__(self, url: str, branch: str, cache_dir: Path | None = None) -> None:
        self.branch = branch
        self.url = url
        key = hashlib.sha256(url.encode()).hexdigest()[:16]
        self._cache = (cache_dir or default_cache_dir()) / key
        git = _git()
        try:
            if not (self._cache / "HEAD").exists():
                self._cache.mkdir(parents=True, exist_ok=True)
                git.Repo.init(self._cache, bare=True).close()
        except (OSError, git.GitCommandError) as exc:
            raise SourceError(f"cannot create the cache clone {self._cache}: {exc}") from None

    @property
    def root(self) -> Path:
        return self._cache

    @property
    def description(self) -> str:
        return redact(self.url)

    def refresh(self) -> None:
        git = _git()
        repo = open_repo(self._cache)
        try:
            repo.git.fetch(
                "--quiet",
                "--no-tags",
                self.url,
                f"+refs/heads/{self.branch}:refs/heads/{self.branch}",
                kill_after_timeout=120,
            )
        except git.GitCommandError as exc:
            detail = " ".join(str(exc.stderr or exc).split())[-300:]
            raise SourceError(f"fetching {self.description} failed: {detail}") from None
        finally:
            repo.close()

    def head(self) -> str:
        repo = open_repo(self._cache)
        try:
            return _resolve(repo, self.branch, self.description)
        finally:
            repo.close()

    def watch(self, wake: Callable[[], None], stop: threading.Event) -> bool:
        return False  # a remote is polled every interval
