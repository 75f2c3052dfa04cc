"""Files the tool reads as secrets, written as a careful operator writes them: mode 0600, from
the start (contract/trust.py refuses a secret that others may read)."""

from __future__ import annotations

import os
from pathlib import Path


def write_private(path: Path, text: str) -> Path:
    """`text` into `path`, mode 0600 whatever the umask; replaces what was there."""
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as out:
        out.write(text)
    os.chmod(path, 0o600)
    return path
